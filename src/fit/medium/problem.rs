//! The medium fit's least-squares problem for the crate `levenberg-marquardt`: residuals of every
//! pixel and channel, (L − E_c · law(cos φ) · M_c(θ; R)) / σ, and a prior's residual on η.
//!
//! Parameters u: ln σa (×3), ln σs′ (×3), ln(η − 1), and without a known irradiance ln E (×3).
//! The Jacobian is by forward differences of step [`STEP`] in u, computed where each column
//! reaches: a channel's σa and σs′ change only its own profiles (one per radius), η all of them,
//! and E enters linearly (its column is −prediction/σ exactly).

use super::pixels::{Px, Radius, Setup};
use crate::model::boundary::Boundary;
use crate::model::dipole::Medium;
use crate::model::sphere_diffusion::{SphereDiffusion, Tabulated};
use crate::model::tangential_flux;
use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Forward-difference step in u. It must exceed the profile's own noise (the beam series is cut
/// where it moves M by 3.4e-5, `BEAM_REACH`): at 1e-3 a relative change of 1e-3 in σ moves M by
/// 1e-4 to 1e-3.
pub(super) const STEP: f64 = 1e-3;

/// Index of ln(η − 1) in u.
pub(super) const ETA: usize = 6;

/// The parameters as the model takes them.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Physical {
    pub(super) media: [Medium; 3],
    pub(super) irradiance: [f64; 3],
    /// The boundary at this η, of the setup's roughness.
    pub(super) boundary: Boundary,
}

/// The range the fit may explore: σa and σs′ (1/mm) and η. Past σt′R of about 150 the sphere is
/// a diffuse surface to the camera (its light spreads under 1/150 of its radius, finer than M's
/// rolled-off series resolves), so σs′ stops at 150 over the largest radius.
pub(super) const SIGMA_A_RANGE: (f64, f64) = (1e-5, 5.0);
pub(super) const ETA_RANGE: (f64, f64) = (1.05, 2.5);
pub(super) const MAX_SIGMA_T_RADIUS: f64 = 150.0;

/// The residual per unit of u beyond the range: a wall that turns the solver back, where the
/// clamped model alone would be flat.
const WALL: f64 = 1e3;

/// How far u lies outside the range, summed over the parameters (0 inside).
fn outside(u: &[f64], setup: &Setup) -> f64 {
    let beyond = |v: f64, (lo, hi): (f64, f64)| (lo.ln() - v).max(0.0) + (v - hi.ln()).max(0.0);
    (0..3)
        .map(|c| {
            beyond(u[c], SIGMA_A_RANGE) + beyond(u[3 + c], sigma_s_range(setup.largest_radius))
        })
        .sum::<f64>()
        + beyond(u[ETA], (ETA_RANGE.0 - 1.0, ETA_RANGE.1 - 1.0))
}

/// The parameters of `p` at the edge of their range (within 0.1%).
pub(super) fn at_bounds(p: &Physical, setup: &Setup) -> Vec<String> {
    let near = |v: f64, (lo, hi): (f64, f64)| v <= lo * 1.001 || v >= hi * 0.999;
    let mut out = vec![];
    for (c, name) in ["r", "g", "b"].iter().enumerate() {
        if near(p.media[c].sigma_a, SIGMA_A_RANGE) {
            out.push(format!("σa_{name}"));
        }
        if near(
            p.media[c].sigma_s_reduced,
            sigma_s_range(setup.largest_radius),
        ) {
            out.push(format!("σs′_{name}"));
        }
    }
    if near(p.media[0].eta, ETA_RANGE) {
        out.push("η".into());
    }
    out
}

/// The range of σs′ on spheres up to `largest` mm.
pub(super) fn sigma_s_range(largest: f64) -> (f64, f64) {
    (1e-3, MAX_SIGMA_T_RADIUS / largest)
}

/// u → the three media, the irradiance per channel (the setup's when given) and the boundary,
/// each held inside its range.
pub(super) fn physical(u: &[f64], setup: &Setup) -> Physical {
    physical_through(u, setup, None)
}

/// [`physical`] with `boundary` when it is already built for u's η (its quadrature is the
/// costly part of a small fit's step).
fn physical_through(u: &[f64], setup: &Setup, boundary: Option<&Boundary>) -> Physical {
    let within = |v: f64, (lo, hi): (f64, f64)| v.clamp(-30.0, 30.0).exp().clamp(lo, hi);
    let eta = 1.0 + within(u[ETA], (ETA_RANGE.0 - 1.0, ETA_RANGE.1 - 1.0));
    let media = std::array::from_fn(|c| Medium {
        sigma_a: within(u[c], SIGMA_A_RANGE),
        sigma_s_reduced: within(u[3 + c], sigma_s_range(setup.largest_radius)),
        eta,
    });
    let irradiance = match setup.irradiance {
        Some(e) => [e; 3],
        None => std::array::from_fn(|c| u[7 + c].clamp(-30.0, 30.0).exp()),
    };
    Physical {
        media,
        irradiance,
        boundary: boundary
            .cloned()
            .unwrap_or_else(|| Boundary::rough(eta, setup.alpha)),
    }
}

/// M(θ) per radius and channel.
pub(super) type Profiles = Vec<[Option<Tabulated>; 3]>;

/// The profiles of `channels` for every radius, in parallel.
pub(super) fn profiles(radii: &[Radius], p: &Physical, channels: &[usize]) -> Profiles {
    let jobs: Vec<(usize, usize)> = (0..radii.len())
        .flat_map(|r| channels.iter().map(move |&c| (r, c)))
        .collect();
    let tables: Vec<Tabulated> = jobs
        .par_iter()
        .map(|&(r, c)| {
            SphereDiffusion::through(&p.media[c], radii[r].radius_mm, &p.boundary).tabulate()
        })
        .collect();
    let mut out: Profiles = radii.iter().map(|_| [None, None, None]).collect();
    for ((r, c), t) in jobs.into_iter().zip(tables) {
        out[r][c] = Some(t);
    }
    out
}

/// The predicted radiance of one pixel: E · law(cos φ) · M(θ), times the exit's azimuthal
/// factor from the flux along the surface ([`tangential_flux`]).
pub(super) fn predicted(
    e: f64,
    medium: &Medium,
    radius_mm: f64,
    boundary: &Boundary,
    table: &Tabulated,
    px: &Px,
) -> f64 {
    let (m, log_slope) = table.at_with_log_slope(px.cos_theta);
    let flux = tangential_flux::factor(
        log_slope,
        (medium.sigma_a + medium.sigma_s_reduced) * radius_mm,
        tangential_flux::coefficient(medium.reduced_albedo()),
        medium.eta,
        px.cos_theta,
        px.cos_phi,
        px.cos_light_view,
    );
    e * boundary.exit_law(px.cos_phi) * m * flux
}

/// The problem at one point u, with its profiles.
pub(super) struct Problem<'a> {
    pub(super) radii: &'a [Radius],
    pub(super) setup: &'a Setup,
    pub(super) u: DVector<f64>,
    pub(super) tables: Profiles,
    /// Profiles computed so far (the cost of the fit).
    pub(super) evaluations: AtomicUsize,
    /// η is held by its prior (the second stage): the solver's Jacobian leaves η's pixel rows
    /// out, since the prior's row outweighs them; [`Problem::jacobian_with`] still gives them.
    pub(super) eta_held: bool,
}

impl<'a> Problem<'a> {
    pub(super) fn new(
        radii: &'a [Radius],
        setup: &'a Setup,
        u: DVector<f64>,
        eta_held: bool,
    ) -> Problem<'a> {
        let mut p = Problem {
            radii,
            setup,
            u: u.clone(),
            tables: Vec::new(),
            evaluations: AtomicUsize::new(0),
            eta_held,
        };
        p.set_params(&u);
        p
    }

    fn count(&self, channels: usize) {
        self.evaluations
            .fetch_add(channels * self.radii.len(), Ordering::Relaxed);
    }

    /// How many residuals: every used channel of every pixel, η's prior and the range's wall.
    pub(super) fn rows(&self) -> usize {
        self.pixel_rows() + 2
    }

    /// The pixels' residuals: every used channel of every pixel.
    pub(super) fn pixel_rows(&self) -> usize {
        self.radii
            .iter()
            .map(|r| r.pixels.iter().map(Vec::len).sum::<usize>())
            .sum::<usize>()
    }

    /// The residuals of channel `c` of every radius under `tables`, in row order, written into
    /// `out` (the other channels' rows left as they are).
    fn channel_residuals(&self, p: &Physical, tables: &Profiles, c: usize, out: &mut [f64]) {
        for (r, radius) in self.radii.iter().enumerate() {
            let t = tables[r][c].as_ref().expect("the channel's profile");
            let at = self.offset(r, c);
            for (k, px) in radius.pixels[c].iter().enumerate() {
                let pred = predicted(
                    p.irradiance[c],
                    &p.media[c],
                    radius.radius_mm,
                    &p.boundary,
                    t,
                    px,
                );
                out[at + k] = (px.radiance - pred) * px.weight;
            }
        }
    }

    /// The first row of radius `r`, channel `c`.
    pub(super) fn offset(&self, r: usize, c: usize) -> usize {
        let before: usize = self.radii[..r]
            .iter()
            .map(|x| x.pixels.iter().map(Vec::len).sum::<usize>())
            .sum();
        before
            + self.radii[r].pixels[..c]
                .iter()
                .map(Vec::len)
                .sum::<usize>()
    }

    /// Every residual at u under `tables`.
    fn all_residuals(&self, u: &DVector<f64>, tables: &Profiles) -> DVector<f64> {
        let p = physical(u.as_slice(), self.setup);
        let mut out = DVector::zeros(self.rows());
        for c in 0..3 {
            self.channel_residuals(&p, tables, c, out.as_mut_slice());
        }
        let at = self.pixel_rows();
        let prior = self.prior_rows(u);
        out[at] = prior[0];
        out[at + 1] = prior[1];
        out
    }

    /// The rows after the pixels': η's prior and the range's wall.
    fn prior_rows(&self, u: &DVector<f64>) -> [f64; 2] {
        let eta = physical(u.as_slice(), self.setup).media[0].eta;
        let (mean, std) = self.setup.eta_prior;
        [(eta - mean) / std, WALL * outside(u.as_slice(), self.setup)]
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.u = x.clone();
        let p = physical(x.as_slice(), self.setup);
        self.tables = profiles(self.radii, &p, &[0, 1, 2]);
        self.count(3);
    }

    fn params(&self) -> DVector<f64> {
        self.u.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let r = self.all_residuals(&self.u, &self.tables);
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.jacobian_with(!self.eta_held)
    }
}

impl Problem<'_> {
    /// The Jacobian; without `eta_pixels`, η's column holds only its prior's row (the pixels'
    /// rows 0, no profile computed for it).
    pub(super) fn jacobian_with(&self, eta_pixels: bool) -> Option<DMatrix<f64>> {
        let base = self.all_residuals(&self.u, &self.tables);
        let mut jac = DMatrix::zeros(self.rows(), self.u.len());
        // A channel's σa and σs′: only its own rows and profiles move, η and the boundary stay.
        let boundary = &physical(self.u.as_slice(), self.setup).boundary;
        for c in 0..3 {
            for k in [c, 3 + c] {
                let mut u = self.u.clone();
                u[k] += STEP;
                let p = physical_through(u.as_slice(), self.setup, Some(boundary));
                let fresh = profiles(self.radii, &p, &[c]);
                self.count(1);
                let mut moved = base.as_slice().to_vec();
                self.channel_residuals(&p, &fresh, c, &mut moved);
                for (row, (a, b)) in moved.iter().zip(base.iter()).enumerate() {
                    jac[(row, k)] = (a - b) / STEP;
                }
            }
        }
        // η: every profile, the boundary and the prior; or the prior alone.
        let mut u = self.u.clone();
        u[ETA] += STEP;
        if eta_pixels {
            let p = physical(u.as_slice(), self.setup);
            let tables = profiles(self.radii, &p, &[0, 1, 2]);
            self.count(3);
            let moved = self.all_residuals(&u, &tables);
            jac.set_column(ETA, &((moved - &base) / STEP));
        } else {
            let at = self.pixel_rows();
            let moved = self.prior_rows(&u);
            jac[(at, ETA)] = (moved[0] - base[at]) / STEP;
            jac[(at + 1, ETA)] = (moved[1] - base[at + 1]) / STEP;
        }
        // The irradiance, linear: ∂r/∂ln E_c = −prediction/σ · σ = −(radiance·w − r).
        if self.setup.irradiance.is_none() {
            for c in 0..3 {
                for (r, radius) in self.radii.iter().enumerate() {
                    let at = self.offset(r, c);
                    for (k, px) in radius.pixels[c].iter().enumerate() {
                        jac[(at + k, 7 + c)] = -(px.radiance * px.weight - base[at + k]);
                    }
                }
            }
        }
        jac.iter().all(|v| v.is_finite()).then_some(jac)
    }
}

#[cfg(test)]
mod tests {
    use super::super::pixels::{Radius, Setup};
    use super::*;
    use nalgebra::Vector3;

    /// Two radii of a medium's own prediction, nudged, without a known irradiance: the Jacobian's
    /// columns against central differences of the residuals (step 1e-3 in u), relative to the
    /// largest entry. The irradiance's analytic columns: measured 1.7e-7 (the central
    /// difference's own h²/6), asserted 5e-7. The profiles' forward differences: measured
    /// 2.3e-5 to 1.9e-4, asserted 6e-4 (with the ratio table interpolated linearly in r they
    /// were 7e-3 to 4e-2 off: the rows move with σt′).
    #[test]
    fn the_jacobian_follows_central_differences() {
        let setup = Setup {
            light: Vector3::z(),
            eta_prior: (1.44, 0.05),
            alpha: 0.1,
            irradiance: None,
            largest_radius: 20.0,
        };
        let truth = [
            -3.0,
            -2.5,
            -2.0,
            0.0,
            -0.1,
            -0.2,
            0.44f64.ln(),
            1.0,
            1.1,
            1.2,
        ];
        let p = physical(&truth, &setup);
        let radii: Vec<Radius> = [10.0, 20.0]
            .iter()
            .map(|&radius_mm| {
                let pixels = std::array::from_fn(|c| {
                    let t =
                        SphereDiffusion::through(&p.media[c], radius_mm, &p.boundary).tabulate();
                    (0..40)
                        .map(|k| {
                            let at = Px {
                                cos_theta: (k as f64 * 3.0).to_radians().cos(),
                                cos_phi: 0.3 + 0.0175 * k as f64,
                                cos_light_view: 0.5,
                                radiance: 0.0,
                                weight: 0.0,
                            };
                            let l = predicted(
                                p.irradiance[c],
                                &p.media[c],
                                radius_mm,
                                &p.boundary,
                                &t,
                                &at,
                            );
                            Px {
                                radiance: l * (1.0 + 0.02 * ((k * 7 % 5) as f64 - 2.0)),
                                weight: 1.0 / (0.01 + 0.01 * l),
                                ..at
                            }
                        })
                        .collect()
                });
                Radius { radius_mm, pixels }
            })
            .collect();
        let at: Vec<f64> = truth.iter().map(|v| v + 0.05).collect();
        let problem = Problem::new(&radii, &setup, DVector::from_vec(at.clone()), false);
        let jac = problem.jacobian().unwrap();
        let largest = jac.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let h = 1e-3;
        for k in 0..at.len() {
            let moved = |d: f64| {
                let mut u = at.clone();
                u[k] += d;
                Problem::new(&radii, &setup, DVector::from_vec(u), false)
                    .residuals()
                    .unwrap()
            };
            let central = (moved(h) - moved(-h)) / (2.0 * h);
            let worst = (0..central.len())
                .map(|i| (jac[(i, k)] - central[i]).abs())
                .fold(0.0f64, f64::max);
            let bound = if k >= 7 { 5e-7 } else { 6e-4 };
            println!("column {k}: {:.2e}", worst / largest);
            assert!(
                worst < bound * largest,
                "column {k}: {worst:e} of {largest:e}"
            );
        }
    }
}
