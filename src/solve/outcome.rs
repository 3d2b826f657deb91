//! The fit of either method and what the options ask around it, as one outcome.

use super::*;

/// What the fit of either method gives the predictions and fit.json.
pub(super) struct Outcome {
    /// What the fit skipped, and why (joins `Loaded::skipped`).
    pub(super) skipped: Vec<String>,
    pub(super) model_choice: Option<ModelChoice>,
    pub(super) model_choice_s: f64,
    pub(super) solve_phases: Vec<(String, f64)>,
    /// The paper's baseline run beside a joint fit.
    pub(super) baseline: Option<BaselineJson>,
    pub(super) params: Params,
    pub(super) std: [f64; N_PARAMS],
    pub(super) std_formal: [f64; N_PARAMS],
    pub(super) jackknife: Option<Jackknife>,
    pub(super) status: [String; N_PARAMS],
    pub(super) free: [bool; N_PARAMS],
    pub(super) correlation: nalgebra::DMatrix<f64>,
    pub(super) specular: bool,
    pub(super) extensions: Extensions,
    pub(super) reduction: Option<ReductionJson>,
    pub(super) convergence: ConvergenceJson,
    pub(super) per_radius: Option<Vec<RadiusFit>>,
    pub(super) paper: Option<paper::PaperFit>,
    pub(super) light_pull: Option<LightPull>,
    /// The model the parameters belong to (what predicts the photos from them).
    pub(super) model: Model,
    /// The dark floor fitted with the material (radiance units), when none was measured.
    pub(super) floor: Option<solver::Floor>,
    pub(super) prior_tension: [f64; N_PARAMS],
    pub(super) light_fit: String,
}

/// The joint fit with what the options ask around it: the extensions (default, named or chosen
/// by held-out error), the light held at the detector's when the shading pulls it too far, the
/// jackknife, the paper's baseline beside it.
pub(super) fn joint_outcome(
    opts: &Options,
    l: &Loaded,
    fitted: &[&SphereData],
    notes: &mut Vec<String>,
) -> Outcome {
    let mut skipped = vec![];
    let mut model_choice = None;
    let mut model_choice_s = 0.0;
    let mut baseline = None;
    let ext = match opts.extensions {
        ExtensionChoice::None => Extensions::default(),
        ExtensionChoice::On(e) => e,
        ExtensionChoice::Default => {
            let radii = distinct_radii(fitted);
            if radii.len() >= DEFAULT_EXTENSION_RADII {
                Extensions {
                    albedo_curvature: true,
                    ..Extensions::default()
                }
            } else {
                skipped.push(format!(
                    "albedo curvature (the default extension): {} radii, it needs {DEFAULT_EXTENSION_RADII}",
                    radii.len()
                ));
                Extensions::default()
            }
        }
        ExtensionChoice::Auto => {
            let t = Instant::now();
            let (mc, e) = choose_extensions(opts, l, fitted);
            model_choice_s = t.elapsed().as_secs_f64();
            notes.push(format!("model: {} ({})", mc.chosen, mc.reason));
            model_choice = Some(mc);
            e
        }
    };
    let mut jf: JointFit = joint::fit_joint(&setup(opts, l, ext, opts.reduction), fitted);
    // A light pulled beyond PULL_WARN of the detector's errors is pulled by the model's
    // error, not supported by the data: hold it at the detector's and refit. Each
    // parameter's shift between the two fits is the light's systematic on it and joins its
    // std (docs/uncertainty.md, "When the shading pulls the light").
    let mut fit_opts = opts.clone();
    let mut light_shift = [0.0; N_PARAMS];
    let pulled = jf.light_pull.filter(|p| p.pull > joint::PULL_WARN);
    if let (LightFit::Prior, Some(pull), Some(_)) = (opts.light_fit, pulled, l.light) {
        fit_opts.light_fit = LightFit::Hold;
        let held = joint::fit_joint(&setup(&fit_opts, l, ext, opts.reduction), fitted);
        let (a, b) = (jf.fit.params.to_vec(), held.fit.params.to_vec());
        light_shift = std::array::from_fn(|k| {
            if held.fit.free[k] {
                (a[k] - b[k]).abs()
            } else {
                0.0
            }
        });
        let moved_sigma0: Vec<String> = (0..3)
            .map(|c| format!("{:.3}", jf.fit.params.material.sigma0_mm[c]))
            .collect();
        notes.push(format!(
            "the light is held at the highlights' estimate: the shading pulled it {:.1} of its errors, further than the data support; with the pulled light σ0 was {} mm, and each parameter's shift between the two fits joins its std",
            pull.pull,
            moved_sigma0.join(", ")
        ));
        jf = JointFit {
            light_pull: Some(pull),
            ..held
        };
        let why = format!("held: the detector's (pulled {:.1} std)", pull.pull);
        jf.status[idx::AZIMUTH] = why.clone();
        jf.status[idx::ELEVATION] = why;
    }
    // A light taken from the detector keeps the detector's error.
    if fit_opts.light_fit == LightFit::Hold && opts.start_light.is_none() {
        if let (Some(s), Some(d)) = (l.light_std, l.light) {
            let el = LightAngles::from_direction(&d).elevation;
            light_shift[idx::AZIMUTH] = s / el.cos().abs().max(1e-3);
            light_shift[idx::ELEVATION] = s;
        }
    }
    let opts = &fit_opts;
    let jack = if opts.jackknife {
        let fitted_ext = Extensions::of_fit(&jf.fit.free);
        let j = jackknife(opts, l, fitted, &jf, fitted_ext);
        if j.is_none() {
            skipped.push(
                "jackknife: fewer than 3 radii, the standard errors are the formal ones".into(),
            );
        }
        j
    } else {
        skipped.push(
            "jackknife: off (--no-jackknife), the standard errors are the formal ones".into(),
        );
        None
    };
    if let Some(fl) = jf.fit.floor {
        let e = pixel_scale(&l.report);
        let show = |v: [f64; 3]| v.map(|x| format!("{:.5}", x * e)).join(", ");
        notes.push(format!(
            "no dark floor measured (the photos around the spheres are lit): fitted with the material, {} ± {} of full scale (r, g, b), and subtracted before the predictions and figures",
            show(fl.value),
            show(fl.std)
        ));
    }
    // The paper's baseline beside it, for the figures and a comparison (on the photos
    // less the fitted floor, when one was fitted: the procedure assumes a measured one).
    let want = opts.baseline || opts.plots.is_some();
    if let (true, Some(light)) = (want, l.light) {
        let t = Instant::now();
        let floored: Vec<SphereData> = match jf.fit.floor {
            Some(fl) => fitted.iter().map(|s| less_floor(s, fl.value)).collect(),
            None => vec![],
        };
        let base: Vec<&SphereData> = if floored.is_empty() {
            fitted.to_vec()
        } else {
            floored.iter().collect()
        };
        let pf = paper::fit(&base, &light, l.highlight_radius, opts.eta_prior.0);
        let a = LightAngles::from_direction(&light);
        baseline = Some(BaselineJson {
            eta: pf.eta,
            light_azimuth_deg: a.azimuth.to_degrees(),
            light_elevation_deg: a.elevation.to_degrees(),
            mask_deg: pf.mask_deg,
            sigma0_mm: pf.params.material.sigma0_mm,
            albedo: pf.params.material.albedo,
            per_radius: pf.per_radius,
            seconds: t.elapsed().as_secs_f64(),
        });
    }
    let solve_phases = jf.phases.clone();
    notes.extend(jf.notes.iter().cloned());
    if !jf.specular {
        skipped.push("specular lobe: off (no usable highlight)".into());
    }
    let setting = match opts.reduction {
        Reduction::Auto => "auto".to_string(),
        Reduction::None => "none".to_string(),
        Reduction::Factor(f) => format!("{}°", f as f64 * 0.25),
    };
    skipped.push(if jf.chosen.width_deg > 0.0 {
        format!(
            "pixels: {} pooled into {} observations ({}° cells, predicted shift {:.2} std)",
            jf.pixels, jf.chosen.observations, jf.chosen.width_deg, jf.chosen.predicted_shift_std
        )
    } else {
        format!("pixels: all {} used", jf.pixels)
    });
    for (name, st) in PARAM_NAMES.iter().zip(&jf.status) {
        if st.starts_with("prior") {
            skipped.push(format!("{name}: {st}"));
        }
    }
    Outcome {
        skipped,
        model_choice,
        model_choice_s,
        solve_phases,
        baseline,
        model: jf.model,
        floor: jf.fit.floor,
        params: jf.fit.params,
        std: std::array::from_fn(|k| {
            let spread = jack.as_ref().map_or(0.0, |j| j.std[k]);
            let s = (jf.fit.std[k].max(spread) * jf.prior_tension[k]).hypot(light_shift[k]);
            if k == idx::ETA {
                s.hypot(jf.eta_systematic)
            } else {
                s
            }
        }),
        prior_tension: jf.prior_tension,
        std_formal: jf.fit.std,
        jackknife: jack,
        status: jf.status.clone(),
        free: jf.fit.free,
        correlation: jf.fit.correlation.clone(),
        specular: jf.specular,
        extensions: Extensions::of_fit(&jf.fit.free),
        reduction: Some(ReductionJson {
            setting,
            pixels: jf.pixels,
            chosen: jf.chosen.clone(),
            levels: jf.levels.clone(),
            shift_limit_std: joint::SHIFT_LIMIT,
        }),
        convergence: ConvergenceJson {
            converged: jf.fit.converged,
            stages: jf.stages.clone(),
            downweighted: jf.downweighted,
            robust_loss: opts
                .robust
                .then(|| format!("huber, k = {}", joint::HUBER_K)),
            chi2_per_dof: Some(jf.chi2_dof),
        },
        per_radius: None,
        paper: None,
        light_pull: jf.light_pull,
        light_fit: if pulled.is_some() && opts.light_fit == LightFit::Hold {
            "prior, then hold".into()
        } else {
            opts.light_fit.name().into()
        },
    }
}

/// The source paper's procedure: the detector's light, the peak masked, Fresnel divided out,
/// σ fitted per radius and combined.
pub(super) fn paper_outcome(
    opts: &Options,
    l: &Loaded,
    fitted: &[&SphereData],
    notes: &mut Vec<String>,
) -> Result<Outcome> {
    let Some(light) = l.light else {
        return Err(Error::invalid(
            &l.report.session_file,
            "--method paper needs the light direction and the detector found no usable highlight",
        ));
    };
    let pf = paper::fit(fitted, &light, l.highlight_radius, opts.eta_prior.0);
    notes.push(format!(
        "paper: light from the detector, specular peak masked within {:.1}° of the mirror direction, exit Fresnel divided out with η = {}, σ fitted per radius",
        pf.mask_deg, pf.eta
    ));
    let mut status: [String; N_PARAMS] = std::array::from_fn(|_| "fixed".to_string());
    for s in status.iter_mut().take(6) {
        *s = "fitted per radius, combined".into();
    }
    status[idx::ETA] = format!("fixed: divided out with η = {}", pf.eta);
    status[idx::KS] = "off: peak masked".into();
    status[idx::ALPHA] = "off: peak masked".into();
    status[idx::AZIMUTH] = "fixed: from the detector".into();
    status[idx::ELEVATION] = "fixed: from the detector".into();
    status[idx::SIGMA_EXPONENT] = "off".into();
    status[idx::ALBEDO_CURVATURE] = "off".into();
    let mut free = [false; N_PARAMS];
    for f in free.iter_mut().take(6) {
        *f = true;
    }
    Ok(Outcome {
        skipped: vec![],
        model_choice: None,
        model_choice_s: 0.0,
        solve_phases: vec![],
        baseline: None,
        model: crate::fit::paper::predicting_model(),
        floor: None,
        prior_tension: [1.0; N_PARAMS],
        params: pf.params,
        std: pf.std,
        std_formal: pf.std,
        jackknife: None,
        status,
        free,
        // Separate fits per radius: no joint covariance to report.
        correlation: nalgebra::DMatrix::zeros(0, 0),
        specular: false,
        extensions: Extensions::default(),
        reduction: None,
        convergence: ConvergenceJson {
            converged: pf.converged,
            stages: vec![],
            downweighted: 0,
            robust_loss: None,
            chi2_per_dof: None,
        },
        per_radius: Some(pf.per_radius.clone()),
        paper: Some(pf),
        light_pull: None,
        light_fit: LightFit::Hold.name().into(),
    })
}
