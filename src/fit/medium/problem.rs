//! The medium fit's least-squares problem for the crate `levenberg-marquardt`: residuals of every
//! pixel and channel, (L − E_c · law(cos φ) · M_c(θ; R)) / σ, and a prior's residual on η.
//!
//! Parameters u: ln σa (×3), ln σs′ (×3), ln(η − 1), ln α (the boundary's roughness; held, its
//! column empty, where the setup gives it no prior), and without a known irradiance ln E (×3).
//! M and the exit law come from the fit's [`SphereAtlas`] (M in dimensionless coordinates,
//! shared by every radius, channel and stage), and so does the Jacobian: analytic, by the chain
//! rule from the atlas's derivatives in x = ln(σt′R), y = ln(1 − α′), η and ln α; E enters
//! linearly. Rows after the pixels': η's prior, the range's wall and α's prior.

use super::pixels::{Px, Radius, Setup};
use crate::model::boundary::Boundary;
use crate::model::dipole::Medium;
use crate::model::exit_tilt;
use crate::model::specular;
use crate::model::sphere_atlas::{Coordinates, ExitLaw, Profile, SphereAtlas};
use crate::model::sphere_diffusion::{SphereDiffusion, Tabulated};
use crate::model::tangential_flux;
use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;

/// Central-difference step in u for the rows after the pixels' (η's prior and the range's
/// wall), which cost nothing to evaluate.
const STEP: f64 = 1e-6;

/// Index of ln(η − 1) in u.
pub(super) const ETA: usize = 6;

/// Index of ln α in u.
pub(super) const ALPHA: usize = 7;

/// Index of the first ln E in u (without a known irradiance).
pub(super) const IRRADIANCE: usize = 8;

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
pub(super) const ALPHA_RANGE: (f64, f64) = (0.005, 0.6);
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
        + if setup.alpha_std.is_some() {
            beyond(u[ALPHA], ALPHA_RANGE)
        } else {
            0.0
        }
}

/// How near its range's edge a parameter is said to have ended there ([`at_bounds`]): within
/// this factor of it. The wall turns the solver back, so a fit the photos pull out of what the
/// model describes need not end on the edge itself: on a physically based render at a corner of
/// the issue's range (σt 0.5 /mm, albedo 0.7–0.8, η 1.6) η ended at 2.48 of 2.5 and α at 0.594
/// of 0.6, with σs′ +200% off against a stated ± 20% (docs/medium.md, "Across the issue's
/// range"). The eleven physically based sessions' values lie 1.5 times or more inside every
/// edge.
pub(super) const EDGE_MARGIN: f64 = 1.05;

/// The parameters of `p` at or near the edge of their range (within [`EDGE_MARGIN`]).
pub(super) fn at_bounds(p: &Physical, setup: &Setup) -> Vec<String> {
    let near = |v: f64, (lo, hi): (f64, f64)| v <= lo * EDGE_MARGIN || v >= hi / EDGE_MARGIN;
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
    if setup.alpha_std.is_some() && near(p.boundary.alpha, ALPHA_RANGE) {
        out.push("α".into());
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
    let (media, irradiance) = media(u, setup);
    Physical {
        media,
        irradiance,
        boundary: Boundary::rough(media[0].eta, roughness(u, setup)),
    }
}

/// u → the boundary's roughness: the setup's where it is held, else held inside its range.
pub(super) fn roughness(u: &[f64], setup: &Setup) -> f64 {
    match setup.alpha_std {
        Some(_) => within(u[ALPHA], ALPHA_RANGE),
        None => setup.alpha,
    }
}

/// u → the three media and the irradiance per channel, each held inside its range.
fn media(u: &[f64], setup: &Setup) -> ([Medium; 3], [f64; 3]) {
    let eta = 1.0 + within(u[ETA], (ETA_RANGE.0 - 1.0, ETA_RANGE.1 - 1.0));
    let media = std::array::from_fn(|c| Medium {
        sigma_a: within(u[c], SIGMA_A_RANGE),
        sigma_s_reduced: within(u[3 + c], sigma_s_range(setup.largest_radius)),
        eta,
    });
    let irradiance = match setup.irradiance {
        Some(e) => [e; 3],
        None => std::array::from_fn(|c| u[IRRADIANCE + c].clamp(-30.0, 30.0).exp()),
    };
    (media, irradiance)
}

/// e^v held within (lo, hi).
fn within(v: f64, (lo, hi): (f64, f64)) -> f64 {
    v.clamp(-30.0, 30.0).exp().clamp(lo, hi)
}

/// d e^v/dv over e^v where e^v lies inside (lo, hi): 1, and 0 where it is held at an edge.
fn free(v: f64, (lo, hi): (f64, f64)) -> f64 {
    let e = v.clamp(-30.0, 30.0).exp();
    if e > lo && e < hi {
        1.0
    } else {
        0.0
    }
}

/// M(θ) of each channel on a sphere of `radius_mm`, computed directly, in parallel (for a
/// prediction outside the fit: the held-out radius, a medium read back from fit.json).
pub(super) fn profiles(radius_mm: f64, p: &Physical) -> [Tabulated; 3] {
    let tables: Vec<Tabulated> = (0..3)
        .into_par_iter()
        .map(|c| SphereDiffusion::through(&p.media[c], radius_mm, &p.boundary).tabulate())
        .collect();
    tables.try_into().expect("three channels")
}

/// The predicted radiance of one pixel: E · law(cos φ) · M(θ), times the exit's azimuthal
/// factor from the flux along the surface ([`tangential_flux`]), plus the surface's own GGX
/// reflection ([`surface`]).
pub(super) fn predicted(
    e: f64,
    medium: &Medium,
    radius_mm: f64,
    boundary: &Boundary,
    table: &Tabulated,
    px: &Px,
) -> f64 {
    let (m, log_slope) = table.at_with_log_slope(px.cos_theta);
    let (flux, _, _) = flux_at(medium, radius_mm, log_slope, px);
    let law = boundary.exit_law(px.cos_phi, medium.reduced_albedo());
    e * (law * m * flux + surface(px, boundary.alpha, medium.eta).value)
}

/// The surface's own reflection at a pixel, F D G / (4 n·v) (n·l) of the boundary's GGX
/// roughness `alpha` and index `eta`, with its derivatives ([`specular::lobe`]; zero on a
/// smooth boundary, whose mirror reflection the fit's pixels leave out). The fit takes pixels
/// whose half vector is more than 25° from the normal, where a GGX lobe of α 0.1 still reflects
/// a few percent of a dark medium's radiance (docs/medium.md, "The surface's reflection beyond
/// the lobe's 25°").
fn surface(px: &Px, alpha: f64, eta: f64) -> specular::LobeEval {
    if alpha < crate::model::boundary::SMOOTH_ALPHA {
        return specular::LobeEval::default();
    }
    specular::lobe(px.cos_theta, px.cos_phi, px.cos_light_view, 1.0, alpha, eta)
}

/// The flux's factor at a pixel ([`tangential_flux::factor`]) with its derivatives, and the
/// derivative of its coefficient in y = ln(1 − α′).
fn flux_at(
    medium: &Medium,
    radius_mm: f64,
    log_slope: f64,
    px: &Px,
) -> (f64, tangential_flux::FactorGradient, f64) {
    let (k, dk_dy) = tangential_flux::coefficient_with_slope(medium.reduced_albedo());
    let (flux, g) = tangential_flux::factor(
        log_slope,
        medium.sigma_t_reduced() * radius_mm,
        k,
        medium.eta,
        px.cos_theta,
        px.cos_phi,
        px.cos_light_view,
    );
    (flux, g, dk_dy)
}

/// [`predicted`] from the atlas's profile and exit law, with `gradient` its derivatives in the
/// atlas's coordinates (x, y, η, ln α): the same product, each factor differentiated (without,
/// zeros). `tilt` is the exit law's for this medium and roughness α ([`exit_tilt::tilt`], the
/// same for every pixel of a channel).
fn predicted_with_gradient(
    e: f64,
    (medium, alpha, tilt): (&Medium, f64, &exit_tilt::Tilt),
    radius_mm: f64,
    law: &ExitLaw,
    profile: &Profile,
    px: &Px,
    gradient: bool,
) -> (f64, [f64; 4]) {
    let at = Tabulated::locate(px.cos_theta);
    let (m, log_slope) = profile.value.at_node(at);
    let (flux, g, dk_dy) = flux_at(medium, radius_mm, log_slope, px);
    let (l, dl_deta, dl_dalpha, dl_dk) = law.at(px.cos_phi, tilt.k);
    let scale = e * l;
    let lobe = surface(px, alpha, medium.eta);
    let value = scale * m * flux + e * lobe.value;
    if !gradient {
        return (value, [0.0; 4]);
    }
    let gradient = std::array::from_fn(|q| {
        let (dm, ds) = profile.d[q].at_node(at);
        let own = match q {
            0 => g.ln_sigma_t_radius,
            1 => g.k * dk_dy,
            2 => g.eta,
            // The flux along the surface does not see the boundary's roughness.
            _ => 0.0,
        };
        let mut v = scale * (dm * flux + m * (g.log_slope * ds + own));
        // The law's, through its own coordinates and through the tilt's.
        match q {
            1 => v += e * dl_dk * tilt.d_y * m * flux,
            2 => v += e * ((dl_deta + dl_dk * tilt.d_eta) * m * flux + lobe.d_eta),
            // The lobe's α derivative, in ln α.
            3 => v += e * ((dl_dalpha + dl_dk * tilt.d_ln_alpha) * m * flux + lobe.d_alpha * alpha),
            _ => {}
        }
        v
    });
    (value, gradient)
}

/// The atlas's profiles, per radius and channel.
type AtlasProfiles = Vec<[Profile; 3]>;

/// The problem at one point u, with its profiles.
pub(super) struct Problem<'a> {
    pub(super) radii: &'a [Radius],
    pub(super) setup: &'a Setup,
    pub(super) u: DVector<f64>,
    pub(super) atlas: &'a SphereAtlas,
    tables: AtlasProfiles,
    law: ExitLaw,
    /// η is held by its prior (the second stage): the solver's Jacobian leaves η's pixel rows
    /// out, since the prior's row outweighs them; [`Problem::jacobian_with`] still gives them.
    pub(super) eta_held: bool,
}

impl<'a> Problem<'a> {
    pub(super) fn new(
        radii: &'a [Radius],
        setup: &'a Setup,
        atlas: &'a SphereAtlas,
        u: DVector<f64>,
        eta_held: bool,
    ) -> Problem<'a> {
        let mut p = Problem {
            radii,
            setup,
            u: u.clone(),
            atlas,
            tables: Vec::new(),
            law: atlas.law(1.0 + u[ETA].exp(), u[ALPHA]),
            eta_held,
        };
        p.set_params(&u);
        p
    }

    /// How many residuals: every used channel of every pixel, η's prior, the range's wall and
    /// α's prior.
    pub(super) fn rows(&self) -> usize {
        self.pixel_rows() + 3
    }

    /// The pixels' residuals: every used channel of every pixel.
    pub(super) fn pixel_rows(&self) -> usize {
        self.radii
            .iter()
            .map(|r| r.pixels.iter().map(Vec::len).sum::<usize>())
            .sum::<usize>()
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

    /// Every residual at the current u, and with `gradient` each pixel row's derivatives in
    /// the atlas's coordinates (x, y, η, ln α) of its channel's prediction.
    fn evaluate(&self, gradient: bool) -> (DVector<f64>, Vec<[f64; 4]>) {
        let (media, irradiance) = media(self.u.as_slice(), self.setup);
        let alpha = roughness(self.u.as_slice(), self.setup);
        let tilts = media
            .each_ref()
            .map(|m| exit_tilt::tilt(m.reduced_albedo(), m.eta, alpha));
        let mut out = DVector::zeros(self.rows());
        let mut grad = vec![[0.0; 4]; if gradient { self.pixel_rows() } else { 0 }];
        for (r, radius) in self.radii.iter().enumerate() {
            for c in 0..3 {
                let at = self.offset(r, c);
                let profile = &self.tables[r][c];
                for (k, px) in radius.pixels[c].iter().enumerate() {
                    let (pred, g) = predicted_with_gradient(
                        irradiance[c],
                        (&media[c], alpha, &tilts[c]),
                        radius.radius_mm,
                        &self.law,
                        profile,
                        px,
                        gradient,
                    );
                    out[at + k] = (px.radiance - pred) * px.weight;
                    if gradient {
                        grad[at + k] = g;
                    }
                }
            }
        }
        let at = self.pixel_rows();
        for (k, v) in self.prior_rows(&self.u).into_iter().enumerate() {
            out[at + k] = v;
        }
        (out, grad)
    }

    /// The rows after the pixels': η's prior, the range's wall and α's prior (0 where α is
    /// held).
    fn prior_rows(&self, u: &DVector<f64>) -> [f64; 3] {
        let eta = media(u.as_slice(), self.setup).0[0].eta;
        let (mean, std) = self.setup.eta_prior;
        let alpha = match self.setup.alpha_std {
            Some(s) => (roughness(u.as_slice(), self.setup) - self.setup.alpha) / s,
            None => 0.0,
        };
        [
            (eta - mean) / std,
            WALL * outside(u.as_slice(), self.setup),
            alpha,
        ]
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.u = x.clone();
        let (media, _) = media(x.as_slice(), self.setup);
        let alpha = roughness(x.as_slice(), self.setup);
        let points: Vec<Coordinates> = self
            .radii
            .iter()
            .flat_map(|r| {
                media
                    .iter()
                    .map(move |m| Coordinates::of(m, r.radius_mm, alpha))
            })
            .collect();
        self.atlas.ensure(&points);
        let profiles: Vec<Profile> = points.par_iter().map(|p| self.atlas.profile(p)).collect();
        let mut profiles = profiles.into_iter();
        self.tables = self
            .radii
            .iter()
            .map(|_| std::array::from_fn(|_| profiles.next().expect("a profile per point")))
            .collect();
        self.law = self.atlas.law(media[0].eta, alpha.ln());
    }

    fn params(&self) -> DVector<f64> {
        self.u.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let r = self.evaluate(false).0;
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.jacobian_with(!self.eta_held)
    }
}

impl Problem<'_> {
    /// The Jacobian; without `eta_pixels`, η's column holds only its prior's row (the pixels'
    /// rows 0).
    ///
    /// A pixel's prediction depends on its channel's σa and σs′ through the atlas's
    /// x = ln(σt′R) and y = ln(σa/σt′): ∂x/∂ln σa = σa/σt′, ∂x/∂ln σs′ = σs′/σt′,
    /// ∂y/∂ln σa = σs′/σt′ = −∂y/∂ln σs′; on η through ∂η/∂ln(η − 1) = η − 1; on ln α
    /// directly. A parameter held at its range's edge, or α held by the setup, has no column.
    /// The rows after the pixels' are differenced centrally (step [`STEP`]).
    pub(super) fn jacobian_with(&self, eta_pixels: bool) -> Option<DMatrix<f64>> {
        let (base, grad) = self.evaluate(true);
        let (media, _) = media(self.u.as_slice(), self.setup);
        let mut jac = DMatrix::zeros(self.rows(), self.u.len());
        let u = self.u.as_slice();
        let eta_free = free(u[ETA], (ETA_RANGE.0 - 1.0, ETA_RANGE.1 - 1.0)) * (media[0].eta - 1.0);
        let alpha_free = match self.setup.alpha_std {
            Some(_) => free(u[ALPHA], ALPHA_RANGE),
            None => 0.0,
        };
        let s_range = sigma_s_range(self.setup.largest_radius);
        for (r, radius) in self.radii.iter().enumerate() {
            for (c, m) in media.iter().enumerate() {
                let share_a = m.sigma_a / m.sigma_t_reduced();
                let share_s = 1.0 - share_a;
                let (fa, fs) = (free(u[c], SIGMA_A_RANGE), free(u[3 + c], s_range));
                let at = self.offset(r, c);
                for (k, px) in radius.pixels[c].iter().enumerate() {
                    let g = grad[at + k];
                    let w = -px.weight;
                    jac[(at + k, c)] = w * fa * (g[0] * share_a + g[1] * share_s);
                    jac[(at + k, 3 + c)] = w * fs * share_s * (g[0] - g[1]);
                    if eta_pixels {
                        jac[(at + k, ETA)] = w * eta_free * g[2];
                    }
                    jac[(at + k, ALPHA)] = w * alpha_free * g[3];
                }
            }
        }
        // η's prior, the wall and α's prior, by differences (no profile involved).
        let at = self.pixel_rows();
        for k in 0..self.u.len() {
            let rows = |d: f64| {
                let mut moved = self.u.clone();
                moved[k] += d;
                self.prior_rows(&moved)
            };
            let (up, down) = (rows(STEP), rows(-STEP));
            for q in 0..3 {
                jac[(at + q, k)] = (up[q] - down[q]) / (2.0 * STEP);
            }
        }
        // The irradiance, linear: ∂r/∂ln E_c = −prediction/σ · σ = −(radiance·w − r).
        if self.setup.irradiance.is_none() {
            for c in 0..3 {
                for (r, radius) in self.radii.iter().enumerate() {
                    let at = self.offset(r, c);
                    for (k, px) in radius.pixels[c].iter().enumerate() {
                        jac[(at + k, IRRADIANCE + c)] = -(px.radiance * px.weight - base[at + k]);
                    }
                }
            }
        }
        jac.iter().all(|v| v.is_finite()).then_some(jac)
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::pixels::{Radius, Setup};
    use super::*;
    use nalgebra::Vector3;

    /// Two radii (10, 20 mm) of a medium's own prediction, nudged by ±4%, without a known
    /// irradiance, the boundary's roughness free: the setup, the radii and the truth's u.
    pub fn fixture() -> (Setup, Vec<Radius>, [f64; 11]) {
        let setup = Setup {
            light: Vector3::z(),
            eta_prior: (1.44, 0.05),
            joint_eta_combined: true,
            eta_alpha_slope: 0.0,
            alpha: 0.11,
            alpha_std: Some(0.03),
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
            0.11f64.ln(),
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
                                members: 1.0,
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
        (setup, radii, truth)
    }

    /// The fixture's medium: the analytic Jacobian's columns against central differences of
    /// the residuals (step 1e-5 in u), relative to the largest entry, α's column with them:
    /// measured at most 7.8e-11 (2026-12-09, the exit's tilt following the albedo, η and α),
    /// asserted 2e-10. The residuals come from the same atlas, so this
    /// checks the chain rule, not the interpolation (`sphere_atlas`'s tests check that).
    #[test]
    fn the_jacobian_follows_central_differences() {
        let (setup, radii, truth) = fixture();
        let at: Vec<f64> = truth.iter().map(|v| v + 0.05).collect();
        let atlas = SphereAtlas::free(setup.alpha);
        let problem = Problem::new(&radii, &setup, &atlas, DVector::from_vec(at.clone()), false);
        let jac = problem.jacobian().unwrap();
        let largest = jac.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let h = 1e-5;
        for k in 0..at.len() {
            let moved = |d: f64| {
                let mut u = at.clone();
                u[k] += d;
                Problem::new(&radii, &setup, &atlas, DVector::from_vec(u), false)
                    .residuals()
                    .unwrap()
            };
            let central = (moved(h) - moved(-h)) / (2.0 * h);
            let worst = (0..central.len())
                .map(|i| (jac[(i, k)] - central[i]).abs())
                .fold(0.0f64, f64::max);
            println!("column {k}: {:.2e}", worst / largest);
            assert!(
                worst < 2e-10 * largest,
                "column {k}: {worst:e} of {largest:e}"
            );
        }
    }
}
