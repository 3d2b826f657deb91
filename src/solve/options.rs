//! What a solve is asked: the job's own options (where, which method, what to reuse, which
//! figures) and the fit's settings ([`Settings`], the one settings type of a fit).

use crate::fit::joint::Settings;
use crate::formats::fit::Method;
use std::path::PathBuf;

#[derive(Clone, Debug)]
pub struct Options {
    pub session: PathBuf,
    /// Where fit.json goes (default: beside session.json).
    pub out: Option<PathBuf>,
    pub method: Method,
    /// A radius left out of the fit and predicted.
    pub holdout: Option<f64>,
    /// Run detection even when detections.json is up to date.
    pub redetect: bool,
    /// Where the figures go (the paper's baseline is then run beside a joint fit: its curves are
    /// drawn).
    pub plots: Option<PathBuf>,
    pub quiet: bool,
    /// The CDRF alone, the medium after it, or the medium where the irradiance is known
    /// (`--model`; [`SolveModel::Auto`], the default).
    pub model: SolveModel,
    /// The fit's settings.
    pub fit: Settings,
}

impl Options {
    pub fn new(session: impl Into<PathBuf>) -> Options {
        Options {
            session: session.into(),
            out: None,
            method: Method::Joint,
            holdout: None,
            redetect: false,
            plots: None,
            quiet: true,
            model: SolveModel::Auto,
            fit: Settings::default(),
        }
    }

    /// The settings the fit runs with: the paper's baseline also runs when figures are asked
    /// for (its curves are drawn).
    pub fn fit_settings(&self) -> Settings {
        Settings {
            baseline: self.fit.baseline || self.plots.is_some(),
            ..self.fit
        }
    }
}

/// Which model `solve` fits the photos with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SolveModel {
    /// The CDRF alone (the source paper's model, extended).
    Cdrf,
    /// The CDRF, then the medium from its light, η and lobe.
    Medium,
    /// The medium after the CDRF where the light's irradiance is known (`--irradiance`, or a
    /// diffuse reference in session.json) and the method is the joint fit; the CDRF alone
    /// otherwise. Chosen on the physically based sessions (docs/medium.md, "Which model is the
    /// default"): the medium predicts a held-out radius better on every one of them, and with the
    /// irradiance its σa and σs′ are measurements; without it they rest on the profile's shape
    /// alone (± 50–140%) at two to five times the solve's time.
    #[default]
    Auto,
}

impl SolveModel {
    /// The model [`SolveModel::Auto`] stands for in a solve by `method` where the light's
    /// irradiance is known or not (`--irradiance`, or session.json's `"reference"`); the others
    /// stand for themselves.
    pub fn resolve(self, method: Method, irradiance_known: bool) -> SolveModel {
        match self {
            SolveModel::Auto if irradiance_known && method == Method::Joint => SolveModel::Medium,
            SolveModel::Auto => SolveModel::Cdrf,
            m => m,
        }
    }

    /// Whether this model needs the outlines drawn for the medium fit too (detections.json's
    /// `medium_outline`: the rim weighed by its contrast as well, where the physically based
    /// renders' outlines come out nearer their truth; docs/measurements/detection.md, "Each
    /// sector weighted by its rim's contrast"). The outlines the CDRF, the highlights and the
    /// light use are the same either way. [`SolveModel::Auto`] is resolved first.
    pub fn medium_outlines(self) -> bool {
        self == SolveModel::Medium
    }
}

/// `opts` with its model resolved ([`SolveModel::resolve`]): the irradiance is known where
/// `--irradiance` gives it or session.json names a diffuse reference (`has_reference`). Without a
/// medium, `skipped` says why and how to ask for it.
pub(super) fn resolved(opts: &Options, has_reference: bool, skipped: &mut Vec<String>) -> Options {
    let known = opts.fit.irradiance.is_some() || has_reference;
    let model = opts.model.resolve(opts.method, known);
    if opts.model == SolveModel::Auto && model == SolveModel::Cdrf {
        skipped.extend(match (known, opts.method) {
            (false, Method::Joint) => Some(
                "medium: the light's irradiance is unknown (no --irradiance, no reference in session.json), so σa and σs′ would not be measured; --model medium fits them anyway (docs/medium.md)",
            ),
            (true, _) => Some("medium: it starts from the joint fit's light, η and lobe (--method joint)"),
            (false, _) => None,
        }
        .map(String::from));
    }
    Options {
        model,
        ..opts.clone()
    }
}
