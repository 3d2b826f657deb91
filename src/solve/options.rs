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
    /// The CDRF alone, or the medium after it (`--model`).
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
            model: SolveModel::Cdrf,
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
    #[default]
    Cdrf,
    /// The CDRF, then the medium from its light, η and lobe.
    Medium,
}

impl SolveModel {
    /// Whether this model needs the outlines drawn for the medium fit too (detections.json's
    /// `medium_outline`: the rim weighed by its contrast as well, where the physically based
    /// renders' outlines come out nearer their truth; docs/measurements/detection.md, "Each
    /// sector weighted by its rim's contrast"). The outlines the CDRF, the highlights and the
    /// light use are the same either way.
    pub fn medium_outlines(self) -> bool {
        self == SolveModel::Medium
    }
}
