//! The blur kernel as two Gaussians (docs/kernel.md): the CDRF of each ([`crate::model::cdrf`],
//! from its table where the model has one, [`crate::model::table`]) mixed by weight.

use crate::model::cdrf::Convolution;
use crate::model::cdrf::{self, eval_series, CdrfEval, Series, SeriesEval};
use crate::model::table::{Slice, Table};

/// The CDRF with a kernel of two Gaussians, (1 − w)·f(θ; σ) + w·f(θ; s·σ): a weight w ∈ [0, 1)
/// moved to a Gaussian s > 1 times wider (docs/kernel.md). Sums of Gaussians approximate
/// diffusion profiles (a sharp core, a long tail); the blur is linear in its kernel, so the closed
/// form and every derivative carry over term by term. w = 0 is the plain CDRF (one evaluation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MixtureEval {
    /// Value and ∂/∂θ, ∂²/∂θ², ∂/∂σ (σ the core's width; the tail's is s·σ).
    pub f: CdrfEval,
    /// ∂f/∂w.
    pub d_weight: f64,
    /// ∂f/∂s.
    pub d_ratio: f64,
    /// ∂f/∂p of a [`Series`] source (0 for the clamped cosine).
    pub d_param: f64,
}

/// How each Gaussian's CDRF is evaluated: the closed form of a convolution, or the wrapped form
/// from its table ([`Table`]) — from the table's slices at the core's and the tail's widths where
/// the caller has them ([`Table::slice`]; each used only at the σ it holds).
#[derive(Clone, Copy)]
pub(crate) enum Blur<'a> {
    Closed(Convolution),
    Table([Option<&'a Slice>; 2]),
}

/// [`MixtureEval`] at (θ, σ) for weight `w` and width ratio `s`, blurring the clamped cosine
/// (`source` None) or a [`Series`] (whose terms have no table: [`Blur::Table`] is then the wrapped
/// closed form).
pub(crate) fn eval(
    theta: f64,
    sigma: f64,
    (w, s): (f64, f64),
    source: Option<&Series>,
    blur: Blur,
) -> MixtureEval {
    let one = |sig: f64, k: usize| match (source, blur) {
        (None, Blur::Table(slices)) => SeriesEval {
            f: match slices[k] {
                Some(sl) if sl.sigma == sig => sl.eval(theta),
                _ => Table::shared().eval(theta, sig),
            },
            d_param: 0.0,
        },
        (None, Blur::Closed(conv)) => SeriesEval {
            f: cdrf::eval(theta, sig, conv),
            d_param: 0.0,
        },
        (Some(series), Blur::Closed(conv)) => eval_series(theta, sig, series, conv),
        (Some(series), Blur::Table(_)) => eval_series(theta, sig, series, Convolution::Wrapped),
    };
    let core = one(sigma, 0);
    if w == 0.0 {
        return MixtureEval {
            f: core.f,
            d_weight: 0.0,
            d_ratio: 0.0,
            d_param: core.d_param,
        };
    }
    let tail = one(s * sigma, 1);
    let mix = |a: f64, b: f64| (1.0 - w) * a + w * b;
    MixtureEval {
        f: CdrfEval {
            value: mix(core.f.value, tail.f.value),
            d_theta: mix(core.f.d_theta, tail.f.d_theta),
            d2_theta: mix(core.f.d2_theta, tail.f.d2_theta),
            d_sigma: mix(core.f.d_sigma, s * tail.f.d_sigma),
        },
        d_weight: tail.f.value - core.f.value,
        d_ratio: w * sigma * tail.f.d_sigma,
        d_param: mix(core.d_param, tail.d_param),
    }
}
