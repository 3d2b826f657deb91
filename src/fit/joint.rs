//! The joint fit: σ0, albedo (per channel), the light direction, the specular lobe (ks, α) and,
//! when the light's irradiance is known, η — from every sphere at once.
//!
//! Stages, each a Levenberg–Marquardt fit ([`crate::fit::solver`]) from the previous one's result:
//! 1. start values from the data: the light from the detector (or, without a highlight, the
//!    radiance-weighted mean normal); σ0 per channel by a search over a log grid with the albedo
//!    solved in closed form at each grid point; α from the detector's lobe fit; ks by linear least
//!    squares on the highlight pixels;
//! 2. the diffuse fit (σ0, albedo, light) on 2° cells without the highlight pixels;
//! 3. the choice of reduction level ([`crate::fit::reduce`]): the coarsest (θ, φ) cells whose predicted
//!    parameter shifts all stay below [`SHIFT_LIMIT`] standard errors or below a fixed tolerance
//!    ([`crate::fit::reduce::tolerance`]: 0.1% of σ0, albedo, α; 1% of ks; 0.002 of η; 0.005° of
//!    light),
//!    then, by the
//!    same test, the largest pixel blocks for the highlight;
//! 4. the full fit with the Huber loss on the chosen cells and the highlight pixels;
//! 5. identifiability: parameters whose standard error is not finite or larger than their
//!    plausible range are held at their prior (η, α), or switched off (ks, the extensions), and
//!    the fit is repeated.

use crate::fit::observe::SphereData;
use crate::fit::reduce::Pooled;
use crate::fit::solver::{self, Fit, Obs, Prior};
use crate::formats::fit::{Level, LightPull, Stage};
use crate::model::fresnel;
use crate::model::{idx, LightAngles, Model, Params, N_PARAMS, PARAM_NAMES};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Largest predicted shift of any parameter that a reduction level may cause (in standard errors;
/// or below the parameter's [`crate::fit::reduce::tolerance`]).
pub(crate) const SHIFT_LIMIT: f64 = crate::fit::reduce::SHIFT_STD;
/// The highlight region pooled in pixel blocks, in detector highlight radii.
pub(crate) const HIGHLIGHT_KEEP: f64 = 1.0;
/// Block sizes (pixels) tried for the highlight, smallest first: a block's bias grows with its
/// size (about 4× a doubling), so the first one out of tolerance ends the search, usually the
/// first one tried (docs/pipeline.md, step 4).
pub(crate) const HIGHLIGHT_BLOCKS: [u32; 4] = [2, 4, 8, 16];
/// Huber threshold (in robust σ of the residuals).
pub(crate) const HUBER_K: f64 = 1.345;
/// Default prior on η (a typical wax, soap or resin).
pub(crate) const ETA_PRIOR: (f64, f64) = (1.45, 0.05);
/// Roughness held when the data cannot determine it.
pub(crate) const ALPHA_PRIOR: f64 = 0.1;
/// Start of the two-Gaussian kernel: tail weight and width ratio.
pub(crate) const KERNEL_START: (f64, f64) = (0.2, 3.0);

/// How many residuals the solver sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reduction {
    /// The coarsest level whose predicted shifts stay below [`SHIFT_LIMIT`] std or tolerance.
    Auto,
    /// Every pixel.
    None,
    /// Cells of this many × 0.25°.
    Factor(u32),
}

/// Which model extensions are on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Extensions {
    pub sigma_exponent: bool,
    pub albedo_curvature: bool,
    /// The blur kernel as two Gaussians ([`crate::model::cdrf::mixture`]).
    #[serde(default)]
    pub two_gaussian: bool,
}

impl Extensions {
    pub fn any(&self) -> bool {
        self.sigma_exponent || self.albedo_curvature || self.two_gaussian
    }

    /// The extensions of a fit: those whose parameters were free.
    pub(crate) fn of_fit(free: &[bool; N_PARAMS]) -> Extensions {
        Extensions {
            sigma_exponent: free[idx::SIGMA_EXPONENT],
            albedo_curvature: free[idx::ALBEDO_CURVATURE],
            two_gaussian: free[idx::KERNEL_WEIGHT],
        }
    }

    pub fn name(&self) -> String {
        let parts: Vec<&str> = [
            (self.two_gaussian, "two-gaussian"),
            (self.sigma_exponent, "sigma-exponent"),
            (self.albedo_curvature, "albedo-curvature"),
        ]
        .iter()
        .filter(|p| p.0)
        .map(|p| p.1)
        .collect();
        if parts.is_empty() {
            "plain".into()
        } else {
            parts.join("+")
        }
    }
}

/// Everything the joint fit is told.
#[derive(Clone, Debug)]
pub struct Setup {
    pub model: Model,
    /// The detector's light (pooling is done around it), or `None`.
    pub light: Option<Vector3<f64>>,
    /// Angular radius of the highlight (pixels within it are kept unpooled).
    pub highlight_radius: Option<f64>,
    /// The detector's roughness, when it fitted a lobe.
    pub alpha: Option<f64>,
    pub eta_prior: (f64, f64),
    /// The light's irradiance in the photos' radiance units: the specular scale is then known
    /// (ks = E) and η is fitted.
    pub irradiance: Option<f64>,
    pub reduction: Reduction,
    pub robust: bool,
    pub extensions: Extensions,
    /// Start values given by the user (instead of those from the data).
    pub start_sigma0: Option<[f64; 3]>,
    pub start_light: Option<LightAngles>,
    /// A previous fit of the same scene to start from: the start-value search and the diffuse
    /// stage are skipped (used to refit subsets, e.g. for held-out errors).
    pub warm: Option<Params>,
    /// How the photometric fit treats the light (see [`LightFit`]).
    pub light_fit: LightFit,
    /// The detector's standard error of its light (radians, the largest axis): the width of the
    /// light's prior under [`LightFit::Prior`].
    pub light_std: Option<f64>,
    /// The photos' dark floor is unknown (lit surroundings): a constant per channel fitted with
    /// the rest ([`solver::fit_with_floor`]; [`Fit::floor`] holds it).
    pub floor: bool,
    /// Run the checks whose refits only feed notes and statuses (σ0 against the limits of what
    /// the data resolve); off for refits whose parameters alone are used (the jackknife's, the
    /// model choice's).
    pub checks: bool,
}

/// How the joint fit treats the light direction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LightFit {
    /// The detector's light is a measurement: it enters as a Gaussian prior (its own standard
    /// error on each angle, widened by [`LIGHT_PRIOR_FLOOR`]), and the shading may move it only as
    /// far as the data support against that.
    #[default]
    Prior,
    /// The light refined by the shading alone (no prior): the behaviour before the prior.
    Free,
    /// The light held at the detector's estimate (or the given start).
    Hold,
}

impl LightFit {
    pub fn name(&self) -> &'static str {
        match self {
            LightFit::Prior => "prior",
            LightFit::Free => "free",
            LightFit::Hold => "hold",
        }
    }
}

impl Stage {
    fn of(name: &str, obs: usize, f: &Fit, t: std::time::Instant) -> Stage {
        Stage {
            name: name.into(),
            observations: obs,
            free: (0..N_PARAMS)
                .filter(|&k| f.free[k])
                .map(|k| PARAM_NAMES[k].to_string())
                .collect(),
            evaluations: f.evaluations,
            termination: f.termination.clone(),
            converged: f.converged,
            cost_start: f.history.first().copied().unwrap_or(f.cost),
            cost_end: f.cost,
            cost_history: f.history.clone(),
            seconds: t.elapsed().as_secs_f64(),
        }
    }
}

/// What [`fit_joint`] returns.
#[derive(Clone, Debug)]
pub struct JointFit {
    pub fit: Fit,
    pub model: Model,
    pub stages: Vec<Stage>,
    pub levels: Vec<Level>,
    /// The level used (width 0: every pixel).
    pub chosen: Level,
    pub pixels: usize,
    pub downweighted: usize,
    /// Why parameters were held or switched off, and other decisions.
    pub notes: Vec<String>,
    /// How each parameter was treated: "fitted", "fixed", "prior …", "off: …".
    pub status: [String; N_PARAMS],
    /// Whether a specular lobe was fitted.
    pub specular: bool,
    /// Seconds spent in each phase (pooling, start values, stages, reduction choice).
    pub phases: Vec<(String, f64)>,
    /// How far the fit moved the detector's light (when the light was free and a detector's
    /// light with its error was given).
    pub light_pull: Option<LightPull>,
    /// Per parameter, the scale factor its stated error takes for the disagreement between its
    /// prior and the data ([`prior_tension`]; 1 without a prior or without disagreement).
    pub prior_tension: [f64; N_PARAMS],
    /// The disagreement between η from the whole fit and from the highlight alone when it is
    /// beyond their errors (0 otherwise; only with the irradiance given).
    pub eta_systematic: f64,
    /// χ²/dof against the measured noise: (residual / noise)² per observation row.
    pub chi2_dof: f64,
}

/// The Particle Data Group's scale factor for a parameter with a prior: the prior (m_p ± σ_p)
/// and the data alone (m_d ± σ_d, recovered from the posterior m ± σ through
/// 1/σ² = 1/σ_p² + 1/σ_d² and m/σ² = m_p/σ_p² + m_d/σ_d²) are two measurements of one quantity;
/// when they disagree by more than their errors allow, S = |m_d − m_p| / √(σ_p² + σ_d²) > 1
/// and the stated error is scaled by S (docs/uncertainty.md). 1 where the data add nothing.
pub fn prior_tension(value: f64, std: f64, prior: &Prior) -> f64 {
    let inv_data = 1.0 / (std * std) - 1.0 / (prior.std * prior.std);
    if !(inv_data > 0.0) || !inv_data.is_finite() {
        return 1.0;
    }
    let var_data = 1.0 / inv_data;
    let m_data = var_data * (value / (std * std) - prior.mean / (prior.std * prior.std));
    let s = (m_data - prior.mean).abs() / (prior.std * prior.std + var_data).sqrt();
    if s.is_finite() {
        s.max(1.0)
    } else {
        1.0
    }
}

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

/// Fit the joint model to the given spheres, in its phases: the light's prior, the diffuse stage,
/// the lobe's start, the parameter set, the reduction level, the full fit with what the data do
/// not determine held, and the checks on its result.
pub fn fit_joint(setup: &Setup, spheres: &[&SphereData]) -> JointFit {
    let model = setup.model;
    let mut notes = vec![];
    let mut status: [String; N_PARAMS] = std::array::from_fn(|_| "fitted".to_string());
    let highlight = setup.light.is_some() && setup.highlight_radius.is_some();
    // Start light.
    let light0 = setup
        .light
        .unwrap_or_else(|| light_from_shading(spheres, setup.eta_prior.0));
    // Pixels pooled with the highlight (in pixel blocks, not (θ, φ) cells): within the detector's
    // highlight radius (twice that was measured to gain nothing and cost 4× the pixels).
    let keep = if highlight {
        HIGHLIGHT_KEEP * setup.highlight_radius.unwrap_or(0.0)
    } else {
        0.0
    };
    let pool = |light: Vector3<f64>| {
        let parts: Vec<crate::fit::reduce::SphereObs> = spheres
            .iter()
            .map(|s| (&s.obs[..], Some(&s.px[..])))
            .collect();
        Pooled::of_spheres(light, keep, &parts)
    };
    let mut phases: Vec<(String, f64)> = vec![];
    let mut clock = std::time::Instant::now();
    let mut lap = |name: &str, phases: &mut Vec<(String, f64)>| {
        phases.push((name.to_string(), clock.elapsed().as_secs_f64()));
        clock = std::time::Instant::now();
    };
    let mut pooled = pool(light0);
    lap("pool", &mut phases);
    let start_light = setup
        .start_light
        .unwrap_or_else(|| LightAngles::from_direction(&light0));
    let (eta_mean, _) = setup.eta_prior;
    let (s0, a0) = if setup.warm.is_some() {
        ([1.0; 3], [1.0; 3])
    } else {
        let coarse = pooled.observations(&pooled.merged(16));
        diffuse_start(&model, &coarse, &start_light, eta_mean, setup.start_sigma0)
    };
    lap("start values", &mut phases);
    let mut p = Params::diffuse(s0, a0, eta_mean, start_light);
    p.material.specular.alpha = setup.alpha.unwrap_or(ALPHA_PRIOR);
    let mut stages = vec![];
    // Stage: diffuse, on 2° cells without the highlight.
    let mut free = [false; N_PARAMS];
    free[..6].fill(true);
    let hold_light = setup.light_fit == LightFit::Hold;
    free[idx::AZIMUTH] = !hold_light;
    free[idx::ELEVATION] = !hold_light;
    let light = LightPrior::of(setup, &mut status);
    if let Some(w) = setup.warm {
        p = w;
    }
    diffuse_stage(
        setup,
        &mut pooled,
        &pool,
        (&mut p, free),
        &light.priors,
        &mut stages,
        &mut notes,
    );
    lap("diffuse stage", &mut phases);
    let mut specular = specular_start(setup, &pooled, highlight, &mut p, &mut status, &mut notes);
    let mut priors = parameter_set(
        setup,
        spheres,
        specular,
        &light.priors,
        (&mut p, &mut free),
        &mut status,
        &mut notes,
    );
    lap("specular start", &mut phases);
    let (final_obs, chosen, levels) =
        choose_reduction(setup.reduction, &pooled, spheres, &model, &p, free);
    if chosen.width_deg == 0.0 && setup.reduction == Reduction::Auto {
        notes.push(format!(
            "no reduction level keeps the predicted shift below {SHIFT_LIMIT} std or its tolerance: every pixel used"
        ));
    }
    lap("reduction choice", &mut phases);
    // Full fit, then identifiability.
    let (fit, downweighted) = fit_identified(
        setup,
        &final_obs,
        (&mut p, &mut free),
        &mut priors,
        &mut specular,
        &mut status,
        &mut stages,
        &mut notes,
    );
    if setup.checks {
        resolution_notes(
            setup,
            spheres,
            &final_obs,
            &fit,
            &priors,
            &mut status,
            &mut notes,
        );
    }
    let (clipped, on) = spheres
        .iter()
        .fold((0, 0), |(c, n), s| (c + s.saturated, n + s.pixels));
    if on > 0 && clipped as f64 > CLIPPED_WARN * on as f64 {
        notes.push(format!(
            "{:.0}% of the sphere pixels are clipped: the fit rests on the rest (near the terminator), where σ0, the albedo and the light trade off — expect biases of several percent; lower the exposure",
            100.0 * clipped as f64 / on as f64
        ));
    }
    let fit = degenerate_check(fit, &mut stages, &mut notes);
    let (chi2, quality) = fit_notes(&fit, spheres, setup.eta_prior, &status[idx::ETA]);
    notes.extend(quality);
    let light_pull = light.pull(setup, &fit, free[idx::AZIMUTH], &mut notes);
    for k in 0..N_PARAMS {
        if !free[k] && status[k] == "fitted" {
            status[k] = "fixed".into();
        }
    }
    let mut tension = [1.0; N_PARAMS];
    for q in priors.iter().filter(|q| fit.free[q.index]) {
        tension[q.index] = prior_tension(fit.params.to_vec()[q.index], fit.std[q.index], q);
    }
    let eta_systematic = eta_from_highlight(setup, &pooled, specular, &fit, &mut notes);
    lap("joint stage", &mut phases);
    // Each note once (the identifiability rounds repeat theirs).
    let mut seen = std::collections::HashSet::new();
    notes.retain(|n| seen.insert(n.clone()));
    JointFit {
        phases,
        fit,
        model,
        stages,
        levels,
        chosen,
        pixels: pooled.pixels,
        downweighted,
        notes,
        status,
        specular,
        light_pull,
        prior_tension: tension,
        eta_systematic,
        chi2_dof: chi2,
    }
}

/// The detector's light as a prior on the light's two angles (none when it is held or free).
struct LightPrior {
    detector: Option<LightAngles>,
    /// The prior's width (radians).
    std: Option<f64>,
    priors: Vec<Prior>,
}

impl LightPrior {
    fn of(setup: &Setup, status: &mut [String; N_PARAMS]) -> LightPrior {
        let hold_light = setup.light_fit == LightFit::Hold;
        // The detector's light as a prior on the two angles: isotropic with the detector's standard
        // error (floored), so the azimuth's is that over cos(elevation).
        let detector = setup.light.map(|l| LightAngles::from_direction(&l));
        let light_prior_std = match (setup.light_fit, detector, setup.light_std) {
            (LightFit::Prior, Some(_), Some(s)) if s.is_finite() => Some(s.max(LIGHT_PRIOR_FLOOR)),
            _ => None,
        };
        let light_priors: Vec<Prior> = match (light_prior_std, detector) {
            (Some(s), Some(d)) => vec![
                Prior {
                    index: idx::AZIMUTH,
                    mean: d.azimuth,
                    std: s / d.elevation.cos().abs().max(1e-3),
                },
                Prior {
                    index: idx::ELEVATION,
                    mean: d.elevation,
                    std: s,
                },
            ],
            _ => vec![],
        };
        if let Some(s) = light_prior_std {
            let what = format!("prior: the detector's ± {:.4}°", s.to_degrees());
            status[idx::AZIMUTH] = what.clone();
            status[idx::ELEVATION] = what;
        }
        if hold_light {
            let why = if setup.start_light.is_some() {
                "fixed: as given"
            } else if setup.light.is_some() {
                "fixed: from the detector"
            } else {
                "fixed: from the shading"
            };
            status[idx::AZIMUTH] = why.into();
            status[idx::ELEVATION] = why.into();
        }
        LightPrior {
            detector,
            std: light_prior_std,
            priors: light_priors,
        }
    }

    /// How far the shading pulled the light from the detector's, in the detector's errors.
    fn pull(
        &self,
        setup: &Setup,
        fit: &Fit,
        light_free: bool,
        notes: &mut Vec<String>,
    ) -> Option<LightPull> {
        let (detector, light_prior_std) = (self.detector, self.std);
        let light_pull = match (detector, setup.light_std) {
            (Some(d), Some(s)) if light_free && s > 0.0 => {
                let moved = fit.params.light.direction().angle(&d.direction());
                Some(LightPull {
                    moved_deg: moved.to_degrees(),
                    detector_std_deg: s.to_degrees(),
                    prior_std_deg: light_prior_std.map(f64::to_degrees),
                    pull: moved / light_prior_std.unwrap_or(s),
                })
            }
            _ => None,
        };
        if let Some(lp) = &light_pull {
            if lp.pull > PULL_WARN {
                notes.push(format!(
                    "the shading pulls the light {:.3}° from the highlights' estimate ({:.1} times its ± {:.4}°): the model does not describe the shading fully{}",
                    lp.moved_deg,
                    lp.pull,
                    lp.prior_std_deg.unwrap_or(lp.detector_std_deg),
                    if light_prior_std.is_some() {
                        ""
                    } else {
                        "; σ0 moves with the light — without --free-light the detector's light is a prior"
                    }
                ));
            }
        }
        light_pull
    }
}

/// The diffuse stage: the material and the light on 2° cells with the highlight left out; the
/// cells pooled again around a light that moved more than 2° (none with a warm start).
fn diffuse_stage(
    setup: &Setup,
    pooled: &mut Pooled,
    pool: &dyn Fn(Vector3<f64>) -> Pooled,
    (p, free): (&mut Params, [bool; N_PARAMS]),
    light_priors: &[Prior],
    stages: &mut Vec<Stage>,
    notes: &mut Vec<String>,
) {
    let model = setup.model;
    for round in 0..if setup.warm.is_some() { 0 } else { 2 } {
        let t = std::time::Instant::now();
        let cells = pooled.merged(8);
        let obs: Vec<Obs> = pooled.observations(&cells);
        let (f, _, _) = solver::fit_robust(
            model,
            &obs,
            &*p,
            free,
            light_priors,
            setup.floor,
            HUBER_K,
            4,
        );
        stages.push(Stage::of(
            "diffuse (2° cells, highlight left out)",
            obs.len(),
            &f,
            t,
        ));
        let moved = f.params.light.direction().angle(&pooled.light);
        *p = f.params;
        // Cells follow the light: pool again around a light that moved by more than 2°.
        if moved > 2f64.to_radians() && round == 0 {
            notes.push(format!(
                "the light moved {:.1}° from its start in the diffuse fit: pixels pooled again around it",
                moved.to_degrees()
            ));
            *pooled = pool(p.light.direction());
        } else {
            break;
        }
    }
}

/// The lobe's start: ks from the highlight's pixels less the diffuse fit (or the irradiance
/// given); without a usable highlight the lobe is off. Returns whether it is on.
fn specular_start(
    setup: &Setup,
    pooled: &Pooled,
    highlight: bool,
    p: &mut Params,
    status: &mut [String; N_PARAMS],
    notes: &mut Vec<String>,
) -> bool {
    let model = setup.model;
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
        p.material.specular.ks = match setup.irradiance {
            Some(e) => e,
            None if den > 0.0 && num > 0.0 => num / den,
            None => 1e-3,
        };
    } else {
        status[idx::KS] = if setup.light.is_none() {
            "off: no usable highlight".into()
        } else {
            "off: no highlight pixels".into()
        };
        status[idx::ALPHA] = status[idx::KS].clone();
        notes.push("no usable highlight: specular lobe off (ks = 0)".into());
    }
    specular
}

/// The parameters of the full fit and their priors: the lobe, η (on its prior unless the
/// irradiance is given), the extensions asked for (3 radii at least), the kernel's start.
fn parameter_set(
    setup: &Setup,
    spheres: &[&SphereData],
    specular: bool,
    light_priors: &[Prior],
    (p, free): (&mut Params, &mut [bool; N_PARAMS]),
    status: &mut [String; N_PARAMS],
    notes: &mut Vec<String>,
) -> Vec<Prior> {
    let (eta_mean, eta_std) = setup.eta_prior;
    let distinct_radii = {
        let mut r: Vec<f64> = spheres.iter().map(|s| s.radius_mm).collect();
        r.sort_by(|a, b| a.total_cmp(b));
        r.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        r.len()
    };
    let mut priors: Vec<Prior> = light_priors.to_vec();
    free[idx::KS] = specular && setup.irradiance.is_none();
    free[idx::ALPHA] = specular;
    free[idx::ETA] = true;
    match setup.irradiance {
        Some(e) => {
            if specular {
                status[idx::KS] = format!("fixed: the given irradiance {e}");
            }
        }
        None => {
            // Without the light's irradiance a free ks absorbs F(η) (docs/pipeline.md, step 6): η rests on its
            // prior, and on the exit transmission T(φ) as far as the data determine it.
            status[idx::ETA] = format!("prior {eta_mean} ± {eta_std}");
            priors.push(Prior {
                index: idx::ETA,
                mean: eta_mean,
                std: eta_std,
            });
        }
    }
    let mut ext = setup.extensions;
    if ext.any() && distinct_radii < 3 {
        notes.push(format!(
            "extensions {} need at least 3 different radii ({} given): off",
            ext.name(),
            distinct_radii
        ));
        ext = Extensions::default();
    }
    free[idx::SIGMA_EXPONENT] = ext.sigma_exponent;
    free[idx::ALBEDO_CURVATURE] = ext.albedo_curvature;
    free[idx::KERNEL_WEIGHT] = ext.two_gaussian;
    free[idx::KERNEL_RATIO] = ext.two_gaussian;
    if ext.two_gaussian && p.material.kernel_weight == 0.0 {
        // Start: a fifth of the weight in a tail three times wider, the core narrowed so that
        // the kernel's variance stays the plain fit's: σ² = (1 − w + w·s²)·σ_core².
        let (w, s) = (KERNEL_START.0, KERNEL_START.1);
        let shrink = (1.0 - w + w * s * s).sqrt();
        p.material.kernel_weight = w;
        p.material.kernel_ratio = s;
        for v in p.material.sigma0_mm.iter_mut() {
            *v /= shrink;
        }
    }
    if !ext.two_gaussian {
        p.material.kernel_weight = 0.0;
        p.material.kernel_ratio = 0.0;
    }
    for (k, on) in [
        (idx::SIGMA_EXPONENT, ext.sigma_exponent),
        (idx::ALBEDO_CURVATURE, ext.albedo_curvature),
        (idx::KERNEL_WEIGHT, ext.two_gaussian),
        (idx::KERNEL_RATIO, ext.two_gaussian),
    ] {
        if !on {
            status[k] = "off".into();
        }
    }
    priors
}

/// The full fit, repeated (at most twice more) with what the data do not determine held: η at
/// its prior, α held, the lobe or an extension off. Returns the fit and the residuals the Huber
/// loss down-weighted.
#[allow(clippy::too_many_arguments)]
fn fit_identified(
    setup: &Setup,
    final_obs: &[Obs],
    (p, free): (&mut Params, &mut [bool; N_PARAMS]),
    priors: &mut Vec<Prior>,
    specular: &mut bool,
    status: &mut [String; N_PARAMS],
    stages: &mut Vec<Stage>,
    notes: &mut Vec<String>,
) -> (Fit, usize) {
    let model = setup.model;
    let (eta_mean, eta_std) = setup.eta_prior;
    let mut downweighted = 0;
    let mut fit = None;
    for attempt in 0..3 {
        let t = std::time::Instant::now();
        let (f, _, down) = if setup.robust {
            solver::fit_robust(
                model,
                final_obs,
                &*p,
                *free,
                priors,
                setup.floor,
                HUBER_K,
                6,
            )
        } else {
            let f = solver::fit_with_floor(model, final_obs, p, *free, priors, setup.floor);
            (f, vec![], 0)
        };
        downweighted = down;
        stages.push(Stage::of(
            if attempt == 0 {
                "joint"
            } else {
                "joint (poorly determined parameters held)"
            },
            final_obs.len(),
            &f,
            t,
        ));
        let poorly = poorly_determined(&f);
        let mut changed = false;
        for k in poorly {
            match k {
                idx::ETA => {
                    if priors.iter().any(|q| q.index == idx::ETA) {
                        continue;
                    }
                    p.material.eta = eta_mean;
                    priors.push(Prior {
                        index: idx::ETA,
                        mean: eta_mean,
                        std: eta_std,
                    });
                    status[k] =
                        format!("prior {eta_mean} ± {eta_std} (free fit: ± {:.3})", f.std[k]);
                    notes.push(format!(
                        "η is not determined by these data (std {:.3}): held at its prior {eta_mean} ± {eta_std}",
                        f.std[k]
                    ));
                }
                idx::ALPHA => {
                    free[k] = false;
                    p.material.specular.alpha = setup.alpha.unwrap_or(ALPHA_PRIOR);
                    status[k] = format!(
                        "held at {} (free fit: ± {:.3})",
                        p.material.specular.alpha, f.std[k]
                    );
                    notes.push(format!("α is not determined (std {:.3}): held", f.std[k]));
                }
                idx::KS => {
                    free[idx::KS] = false;
                    free[idx::ALPHA] = false;
                    p.material.specular.ks = 0.0;
                    *specular = false;
                    status[idx::KS] = format!("off: not determined (free fit: ± {:.3})", f.std[k]);
                    status[idx::ALPHA] = "off".into();
                    notes.push("the specular scale is not determined: lobe off".into());
                }
                idx::SIGMA_EXPONENT | idx::ALBEDO_CURVATURE => {
                    free[k] = false;
                    status[k] = format!("off: not determined (free fit: ± {:.3})", f.std[k]);
                    notes.push(format!("{} is not determined: off", PARAM_NAMES[k]));
                }
                idx::KERNEL_WEIGHT | idx::KERNEL_RATIO => {
                    if !free[idx::KERNEL_WEIGHT] {
                        continue;
                    }
                    free[idx::KERNEL_WEIGHT] = false;
                    free[idx::KERNEL_RATIO] = false;
                    status[idx::KERNEL_WEIGHT] =
                        format!("off: not determined (free fit: ± {:.3})", f.std[k]);
                    status[idx::KERNEL_RATIO] = "off".into();
                    notes.push("the kernel's shape is not determined: one Gaussian".into());
                }
                _ => {
                    notes.push(format!(
                        "{} is poorly determined (std {:.3} for {:.4})",
                        PARAM_NAMES[k],
                        f.std[k],
                        f.params.to_vec()[k]
                    ));
                    continue;
                }
            }
            if k == idx::SIGMA_EXPONENT {
                p.material.sigma_exponent = 0.0;
            }
            if k == idx::ALBEDO_CURVATURE {
                p.material.albedo_curvature = 0.0;
            }
            if k == idx::KERNEL_WEIGHT || k == idx::KERNEL_RATIO {
                // Back to one Gaussian of the mixture's width.
                let m = f.params.material;
                let grow = (1.0 - m.kernel_weight
                    + m.kernel_weight * m.kernel_ratio * m.kernel_ratio)
                    .sqrt();
                p.material.sigma0_mm = m.sigma0_mm.map(|v| v * grow);
                p.material.kernel_weight = 0.0;
                p.material.kernel_ratio = 0.0;
            }
            changed = true;
        }
        if !changed || attempt == 2 {
            fit = Some(f);
            break;
        }
        // Keep what was fitted for the rest as the next start.
        let held = *p;
        *p = f.params;
        for k in 0..N_PARAMS {
            if !free[k] {
                let mut v = p.to_vec();
                v[k] = held.to_vec()[k];
                *p = Params::from_vec(&v);
            }
        }
    }
    (fit.expect("the loop ends with a fit"), downweighted)
}

/// σ0 at the edges of what the data resolve, where the linearised standard error means nothing:
/// compared with σ0 → 0 or → ∞ (profile likelihood), and below a pixel's angle; each such σ0's
/// status says it is a bound.
fn resolution_notes(
    setup: &Setup,
    spheres: &[&SphereData],
    final_obs: &[Obs],
    fit: &Fit,
    priors: &[Prior],
    status: &mut [String; N_PARAMS],
    notes: &mut Vec<String>,
) {
    let (r_min, r_max) = spheres.iter().fold((f64::INFINITY, 0.0f64), |(a, b), s| {
        (a.min(s.radius_mm), b.max(s.radius_mm))
    });
    let mut limits = resolution_limits(
        setup.model,
        final_obs,
        fit,
        priors,
        setup.floor,
        (r_min, r_max),
    );
    // Below a pixel: the blur σ = σ0/r is smaller than one pixel's angle on the sphere (1/R for a
    // sphere R pixels in radius) on every sphere, so the pixels' own footprint hides it.
    for c in 0..3 {
        let s0 = fit.params.material.sigma0_mm[c];
        let finest = spheres
            .iter()
            .filter(|s| s.pixels > 0)
            .map(|s| (s0 / s.radius_mm) * (s.pixels as f64 / std::f64::consts::PI).sqrt())
            .fold(0.0, f64::max);
        if fit.free[idx::SIGMA0 + c] && finest < 1.0 && !limits.iter().any(|l| l.0 == c) {
            limits.push((c, Bound::Pixel(finest)));
        }
    }
    for (c, bound) in limits {
        let v = fit.params.material.sigma0_mm[c];
        let (what, test) = match bound {
            Bound::Pixel(f) => (
                format!("upper bound: the blur is {f:.2} of a pixel's angle"),
                format!("its blur σ0/r is {f:.2} of a pixel's angle on the sphere or less"),
            ),
            Bound::Zero(d) => (
                format!("upper bound: σ0 → 0 fits as well (Δχ² = {d:.2})"),
                format!("σ0 → 0 fits as well (Δχ² = {d:.2} < {RESOLVED_CHI2})"),
            ),
            Bound::Infinite(d) => (
                format!("lower bound: σ0 → ∞ fits as well (Δχ² = {d:.2})"),
                format!("σ0 → ∞, a uniform glow, fits as well (Δχ² = {d:.2} < {RESOLVED_CHI2})"),
            ),
        };
        status[idx::SIGMA0 + c] = what;
        notes.push(format!(
            "{} = {v:.4} mm is beyond what the data resolve: {test} (radii {r_min}–{r_max} mm); the value is a bound, not a measurement",
            PARAM_NAMES[idx::SIGMA0 + c]
        ));
    }
}

/// A fit whose core parameters have no finite standard error is degenerate, whatever the
/// optimiser's stopping test said: not a measurement.
fn degenerate_check(fit: Fit, stages: &mut [Stage], notes: &mut Vec<String>) -> Fit {
    let mut fit = fit;
    let core = (0..6).chain([idx::AZIMUTH, idx::ELEVATION]);
    let singular: Vec<&str> = core
        .filter(|&k| fit.free[k] && !fit.std[k].is_finite())
        .map(|k| PARAM_NAMES[k])
        .collect();
    if !singular.is_empty() && fit.converged {
        fit.converged = false;
        fit.termination = format!(
            "degenerate: no finite standard error for {}",
            singular.join(", ")
        );
        if let Some(st) = stages.last_mut() {
            st.converged = false;
            st.termination = fit.termination.clone();
        }
        notes.push(format!(
            "the fit is degenerate (the covariance is singular for {}): the result is not a measurement — check the detections and the photos' noise and exposure",
            singular.join(", ")
        ));
    }
    fit
}

/// With the irradiance given, η is measured by the highlight's height — and, through the
/// transmissions, by the diffuse shading, the least exact part of the model. η (and α) refitted
/// on the highlight's pixels alone, the rest held: a disagreement beyond the two formal errors is
/// flagged and returned, to join η's error as a systematic (docs/uncertainty.md, "η").
fn eta_from_highlight(
    setup: &Setup,
    pooled: &Pooled,
    specular: bool,
    fit: &Fit,
    notes: &mut Vec<String>,
) -> f64 {
    let model = setup.model;
    let mut eta_systematic = 0.0;
    if setup.irradiance.is_some() && specular && fit.free[idx::ETA] && pooled.kept.len() > 8 {
        let mut hl_free = [false; N_PARAMS];
        hl_free[idx::ETA] = true;
        hl_free[idx::ALPHA] = fit.free[idx::ALPHA];
        let kept = solver::less_floor(&pooled.kept, fit.floor_value());
        let hl = solver::fit(model, &kept, &fit.params, hl_free, &[]);
        let (a, b) = (hl.params.material.eta, fit.params.material.eta);
        let combined = (hl.std[idx::ETA].powi(2) + fit.std[idx::ETA].powi(2)).sqrt();
        if hl.converged && combined > 0.0 && (a - b).abs() > 3.0 * combined {
            eta_systematic = (a - b).abs();
            notes.push(format!(
                "η = {b:.4} from the joint fit, {a:.4} ± {:.4} from the highlight alone ({:.1} of their errors apart): the diffuse shading pulls η through the transmissions; the difference joins η's std",
                hl.std[idx::ETA],
                (a - b).abs() / combined
            ));
        }
    }
    eta_systematic
}

/// What the fit's residuals and geometry say about it: the residuals against the measured noise
/// (returned as χ²/dof), a light beside the camera, and η against its prior. Returns χ²/dof and
/// the notes.
fn fit_notes(
    fit: &Fit,
    spheres: &[&SphereData],
    (eta_mean, eta_std): (f64, f64),
    eta_status: &str,
) -> (f64, Vec<String>) {
    let mut notes = vec![];
    // Goodness of fit against the measured noise (weights are 1/σ per pixel and channel).
    let dof = fit
        .residuals
        .saturating_sub(fit.free.iter().filter(|f| **f).count())
        .saturating_sub(if fit.floor.is_some() { 3 } else { 0 })
        .max(1);
    let chi2 = 2.0 * fit.cost / dof as f64;
    if chi2 > CHI2_WARN {
        notes.push(format!(
            "the residuals are {:.1}× the measured noise (χ²/dof = {chi2:.1}): the model does not describe these photos fully — check the detections (light, outlines); a wrong light or outline biases σ0",
            chi2.sqrt()
        ));
    }
    // A light beside the camera: θ ≈ φ everywhere, the blur and the exit transmission trade off.
    let view: Vector3<f64> = spheres
        .iter()
        .filter_map(|s| s.obs.first())
        .map(|o| o.geometry.view)
        .sum();
    if view.norm() > 0.0 {
        let a = fit.params.light.direction().angle(&view).to_degrees();
        if a < NEAR_VIEW_DEG {
            notes.push(format!(
                "the light is {a:.1}° from the camera's direction: no terminator in view and θ ≈ φ on every pixel, so σ0 rests on the fall-off at the rim, where it trades off with the exit transmission T(φ; η) — expect σ0 off by 10% or more; light the spheres from the side"
            ));
        }
    }
    let tension = (fit.params.material.eta - eta_mean).abs() / eta_std;
    if eta_status.starts_with("prior") && tension > 3.0 {
        notes.push(format!(
            "η = {:.4} lies {tension:.1} prior σ from the prior {eta_mean} ± {eta_std}: the prior or the model's fall-off at the rim and the terminator disagrees with the data (its std is scaled for the disagreement); measure η with --irradiance",
            fit.params.material.eta
        ));
    }
    if eta_status.starts_with("prior") && fit.std[idx::ETA] < 0.5 * eta_std {
        notes.push(format!(
            "η = {:.4} (formal ± {:.4}): the data, through the Fresnel transmissions, determine η better than its prior (± {eta_std}); that rests on the model's fall-off at the terminator and the rim",
            fit.params.material.eta, fit.std[idx::ETA]
        ));
    }
    (chi2, notes)
}

/// The reduction level (docs/pipeline.md, step 4): angular cells first (the highlight pixel by
/// pixel), then the highlight's pixel blocks, each the coarsest whose predicted shift is within
/// tolerance under `Reduction::Auto`. Returns the observations the joint stage fits, the level
/// chosen (width 0: every pixel) and the levels tried.
fn choose_reduction(
    reduction: Reduction,
    pooled: &Pooled,
    spheres: &[&SphereData],
    model: &Model,
    p: &Params,
    free: [bool; N_PARAMS],
) -> (Vec<Obs>, Level, Vec<Level>) {
    let mut levels = vec![];
    let level = |f: u32, b: u32, n: usize, shift: &crate::fit::reduce::Shift| Level {
        width_deg: f as f64 * 0.25,
        highlight_block_px: b,
        observations: n,
        predicted_shift_std: shift.max_std,
        within_tolerance: shift.within_tolerance,
        limiting: shift.limiting.map(|k| PARAM_NAMES[k].to_string()),
    };
    // Angular cells first (the highlight pixel by pixel), then the highlight's pixel blocks; the
    // cells chosen are kept for the fit.
    let (chosen_factor, block, chosen_cells) = match reduction {
        Reduction::None => (None, 1, None),
        Reduction::Factor(f) => {
            let mut cells = pooled.merged(f);
            cells.extend(pooled.highlight_cells(1));
            (Some(f), 1, Some(cells))
        }
        Reduction::Auto => {
            let single = pooled.highlight_cells(1);
            let mut pyramid = pooled.pyramid();
            let mut pick = None;
            for (k, (f, cells)) in pyramid.iter().enumerate().rev() {
                let shift = pooled.shift(cells, &single, model, p, free);
                levels.push(level(*f, 1, cells.len() + single.len(), &shift));
                if shift.within_tolerance {
                    pick = Some(k);
                    break;
                }
            }
            match pick {
                None => (None, 1, None),
                Some(k) => {
                    let (f, mut angular) = pyramid.swap_remove(k);
                    let mut highlight = (1, single);
                    for b in HIGHLIGHT_BLOCKS {
                        if pooled.kept.len() < 4 * (b * b) as usize {
                            continue;
                        }
                        let hl = pooled.highlight_cells(b);
                        let shift = pooled.shift(&angular, &hl, model, p, free);
                        levels.push(level(f, b, angular.len() + hl.len(), &shift));
                        if !shift.within_tolerance {
                            break;
                        }
                        highlight = (b, hl);
                    }
                    angular.extend(highlight.1);
                    (Some(f), highlight.0, Some(angular))
                }
            }
        }
    };
    let final_obs = match &chosen_cells {
        Some(cells) => pooled.observations(cells),
        // Every pixel.
        None => spheres.iter().flat_map(|s| s.obs.iter().cloned()).collect(),
    };
    let tried = levels.iter().find(|l| {
        Some(l.width_deg) == chosen_factor.map(|f| f as f64 * 0.25) && l.highlight_block_px == block
    });
    let chosen = Level {
        width_deg: chosen_factor.map_or(0.0, |f| f as f64 * 0.25),
        highlight_block_px: block,
        observations: final_obs.len(),
        predicted_shift_std: tried.map_or(0.0, |l| l.predicted_shift_std),
        within_tolerance: tried.is_none_or(|l| l.within_tolerance),
        limiting: tried.and_then(|l| l.limiting.clone()),
    };
    (final_obs, chosen, levels)
}

/// A pull of the light beyond this many standard errors gets a note.
pub const PULL_WARN: f64 = 3.0;
/// Floor on the light prior's width (radians): the detector's modelling error that its own
/// statistics do not see.
pub(crate) const LIGHT_PRIOR_FLOOR: f64 = crate::detect::LIGHT_FLOOR;

/// A light closer than this to the viewing direction (degrees) gets a note: θ ≈ φ.
pub(crate) const NEAR_VIEW_DEG: f64 = 15.0;
/// Above this χ²/dof (residuals twice the measured noise) the fit warns.
pub(crate) const CHI2_WARN: f64 = 4.0;
/// Above this fraction of clipped sphere pixels the fit warns.
pub(crate) const CLIPPED_WARN: f64 = 0.5;

/// Δχ² below which σ0 → 0 or → ∞ counts as fitting the data as well (3σ for one parameter).
pub(crate) const RESOLVED_CHI2: f64 = 9.0;
/// σ = σ0/r below this at the largest radius, or above this at the smallest, is checked against
/// the limits (radians).
const SIGMA_CHECK: (f64, f64) = (0.05, 1.5);

/// Which end of the scale a channel's σ0 cannot be told from, with its Δχ².
#[derive(Clone, Copy, Debug, PartialEq)]
enum Bound {
    /// σ0/r below a pixel's angle on every sphere (the largest fraction).
    Pixel(f64),
    Zero(f64),
    Infinite(f64),
}

/// Channels whose σ0 the data cannot tell from 0 or ∞: for each channel with σ0/r_max small or
/// σ0/r_min large, the fit is repeated (plain least squares) with that σ0 held at 10⁻⁶ mm or
/// 10⁶ mm, and the cost compared with the free refit's in units of the residual variance.
/// `floor`: the dark floor is fitted ([`Setup::floor`]); `radii`: the smallest and largest.
fn resolution_limits(
    model: Model,
    obs: &[Obs],
    fit: &Fit,
    priors: &[Prior],
    floor: bool,
    (r_min, r_max): (f64, f64),
) -> Vec<(usize, Bound)> {
    let s0 = fit.params.material.sigma0_mm;
    let suspects: Vec<(usize, bool)> = (0..3)
        .filter_map(|c| {
            if !fit.free[idx::SIGMA0 + c] {
                None
            } else if s0[c] / r_max < SIGMA_CHECK.0 {
                Some((c, true))
            } else if s0[c] / r_min > SIGMA_CHECK.1 {
                Some((c, false))
            } else {
                None
            }
        })
        .collect();
    if suspects.is_empty() {
        return vec![];
    }
    let free_fit = solver::fit_with_floor(model, obs, &fit.params, fit.free, priors, floor);
    let n = fit.free.iter().filter(|f| **f).count();
    let dof = free_fit.residuals.saturating_sub(n).max(1) as f64;
    let var = 2.0 * free_fit.cost / dof;
    if !(var.is_finite() && var > 0.0) {
        return vec![];
    }
    suspects
        .into_iter()
        .filter_map(|(c, small)| {
            let mut p = free_fit.params;
            p.material.sigma0_mm[c] = if small { 1e-6 } else { 1e6 };
            let mut free = fit.free;
            free[idx::SIGMA0 + c] = false;
            let held = solver::fit_with_floor(model, obs, &p, free, priors, floor);
            let d = 2.0 * (held.cost - free_fit.cost) / var;
            (d < RESOLVED_CHI2).then_some((
                c,
                if small {
                    Bound::Zero(d.max(0.0))
                } else {
                    Bound::Infinite(d.max(0.0))
                },
            ))
        })
        .collect()
}

/// Free parameters the data leave undetermined: a standard error that is not finite, or larger
/// than the parameter's plausible range (relative 50% for positive ones, 0.5 for η − 1, 1 for the
/// extensions, 10° for the light angles).
pub(crate) fn poorly_determined(f: &Fit) -> Vec<usize> {
    let p = f.params.to_vec();
    (0..N_PARAMS)
        .filter(|&k| f.free[k])
        .filter(|&k| {
            let s = f.std[k];
            !s.is_finite()
                || match k {
                    idx::ETA => s > 0.5,
                    idx::AZIMUTH | idx::ELEVATION => s > 10f64.to_radians(),
                    idx::SIGMA_EXPONENT | idx::ALBEDO_CURVATURE => s > 1.0,
                    _ => s > 0.5 * p[k].abs(),
                }
        })
        .collect()
}

/// Relative RMSE of the model against a sphere's pixels (every `stride`-th), over all of them,
/// the lit ones (θ < 90° from the given light) and the unlit ones.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    pub pixels: usize,
    pub rmse: f64,
    pub rel_rmse: f64,
    pub lit_rel_rmse: f64,
    pub unlit_rel_rmse: f64,
}

/// `floor`: the dark floor still in the sphere's observations (a fitted one, [`Fit::floor`]), taken
/// off them first.
pub fn predict(
    model: &Model,
    p: &Params,
    s: &SphereData,
    floor: [f64; 3],
    max_pixels: usize,
) -> Prediction {
    use rayon::prelude::*;
    let stride = (s.obs.len() / max_pixels.max(1)).max(1);
    let l = p.light.direction();
    let sums = s
        .obs
        .par_iter()
        .step_by(stride)
        .map(|o| {
            let m = model.radiance(p, &o.geometry);
            let lit = o.geometry.normal.dot(&l) > 0.0;
            let mut a = [0.0; 6];
            for ((mc, oc), f) in m.iter().zip(&o.radiance).zip(&floor) {
                let oc = oc - f;
                let (d2, o2) = ((mc - oc).powi(2), oc.powi(2));
                let k = if lit { 0 } else { 2 };
                a[k] += d2;
                a[k + 1] += o2;
                a[4] += d2;
                a[5] += o2;
            }
            (a, 1usize)
        })
        .collect::<Vec<_>>()
        .into_iter()
        // In pixel order: the same result on every run.
        .fold(([0.0; 6], 0), |(a, n), (b, m)| {
            (std::array::from_fn(|i| a[i] + b[i]), n + m)
        });
    let (a, n) = sums;
    let rel = |d: f64, o: f64| if o > 0.0 { (d / o).sqrt() } else { f64::NAN };
    Prediction {
        pixels: n,
        rmse: (a[4] / (3 * n.max(1)) as f64).sqrt(),
        rel_rmse: rel(a[4], a[5]),
        lit_rel_rmse: rel(a[0], a[1]),
        unlit_rel_rmse: rel(a[2], a[3]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prior_tension_is_the_pdg_scale_factor() {
        let prior = Prior {
            index: idx::ETA,
            mean: 0.0,
            std: 1.0,
        };
        // Data 5 ± 1 against the prior 0 ± 1: posterior 2.5 ± 1/√2, and the two measurements
        // disagree by 5 / √2 of their combined error.
        let s = prior_tension(2.5, 0.5f64.sqrt(), &prior);
        assert!((s - 5.0 / 2f64.sqrt()).abs() < 1e-12, "{s}");
        // Data 1 ± 1: within their errors, no scaling.
        assert_eq!(prior_tension(0.5, 0.5f64.sqrt(), &prior), 1.0);
        // Data that add nothing (posterior = prior) or a degenerate std: 1.
        assert_eq!(prior_tension(0.0, 1.0, &prior), 1.0);
        assert_eq!(prior_tension(0.3, 0.0, &prior), 1.0);
        // Very precise data far from the prior: S → |m − m_p| / σ_p.
        let s = prior_tension(3.0, 1e-4, &prior);
        assert!((s - 3.0).abs() < 1e-3, "{s}");
    }
}
