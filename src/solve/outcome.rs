//! The fit of either method (the joint fit with what the settings ask around it, or the paper's
//! procedure), as one outcome for the predictions and fit.json.

use super::load::Loaded;
use super::Options;
use crate::error::{Error, Result};
use crate::fit::joint::{self, Extensions, Jackknife, LightFit, Reduction, Session};
use crate::fit::observe::SphereData;
use crate::fit::{paper, solver};
use crate::formats::fit::{
    BaselineJson, ConvergenceJson, LightPull, ModelChoice, RadiusFit, ReductionJson,
};
use crate::model::{idx, Model, Params, N_PARAMS};

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

impl Outcome {
    /// A joint fit's session as an outcome.
    pub(super) fn joint(s: Session) -> Outcome {
        let jf = s.fit;
        let setting = match s.settings.reduction {
            Reduction::Auto => "auto".to_string(),
            Reduction::None => "none".to_string(),
            Reduction::Factor(f) => format!("{}°", f as f64 * 0.25),
        };
        Outcome {
            skipped: s.skipped,
            model_choice: s.model_choice,
            model_choice_s: s.model_choice_s,
            solve_phases: jf.phases,
            baseline: s.baseline,
            model: jf.model,
            floor: jf.fit.floor,
            params: jf.fit.params,
            std: s.std,
            prior_tension: jf.prior_tension,
            std_formal: jf.fit.std,
            jackknife: s.jackknife,
            status: jf.status,
            free: jf.fit.free,
            correlation: jf.fit.correlation,
            specular: jf.specular,
            extensions: Extensions::of_fit(&jf.fit.free),
            reduction: Some(ReductionJson {
                setting,
                pixels: jf.pixels,
                chosen: jf.chosen,
                levels: jf.levels,
                shift_limit_std: joint::SHIFT_LIMIT,
            }),
            convergence: ConvergenceJson {
                converged: jf.fit.converged,
                stages: jf.stages,
                downweighted: jf.downweighted,
                robust_loss: s
                    .settings
                    .robust
                    .then(|| format!("huber, k = {}", joint::HUBER_K)),
                chi2_per_dof: Some(jf.chi2_dof),
            },
            per_radius: None,
            paper: None,
            light_pull: jf.light_pull,
            light_fit: s.light_fit,
        }
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
    let Some(light) = l.measured.light else {
        return Err(Error::invalid(
            &l.report.session_file,
            "--method paper needs the light direction and the detector found no usable highlight",
        ));
    };
    let pf = paper::fit(
        fitted,
        &light,
        l.measured.highlight_radius,
        opts.fit.eta_prior.0,
    );
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
