//! The blur kernel as two Gaussians (docs/kernel.md): the CDRF of each ([`crate::model::cdrf`],
//! from its table where the model has one, [`crate::model::table`]) mixed by weight.

use crate::model::cdrf::Convolution;
use crate::model::cdrf::{self, eval_series, CdrfEval, Series, SeriesEval};
use crate::model::lanes::Real;
use crate::model::table::{Slice, Table};

/// The CDRF with a kernel of two Gaussians, (1 − w)·f(θ; σ) + w·f(θ; s·σ): a weight w ∈ [0, 1)
/// moved to a Gaussian s > 1 times wider (docs/kernel.md). Sums of Gaussians approximate
/// diffusion profiles (a sharp core, a long tail); the blur is linear in its kernel, so the closed
/// form and every derivative carry over term by term. w = 0 is the plain CDRF (one evaluation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MixtureEval<T = f64> {
    /// Value and ∂/∂θ, ∂²/∂θ², ∂/∂σ (σ the core's width; the tail's is s·σ).
    pub f: CdrfEval<T>,
    /// ∂f/∂w.
    pub d_weight: T,
    /// ∂f/∂s.
    pub d_ratio: T,
    /// ∂f/∂p of a [`Series`] source (0 for the clamped cosine).
    pub d_param: T,
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
    let tail = (w != 0.0).then(|| one(s * sigma, 1));
    let part = |e: SeriesEval| (e.f, e.d_param);
    mix(part(core), tail.map(part), sigma, (w, s))
}

/// The two Gaussians' CDRFs (each with ∂f/∂p of its source) mixed at weight `w`, width ratio `s`
/// and core width σ: [`MixtureEval`]; no tail, the core alone (w = 0). On one pixel or four
/// ([`Real`]).
#[inline(always)]
pub(crate) fn mix<T: Real>(
    (core, core_param): (CdrfEval<T>, T),
    tail: Option<(CdrfEval<T>, T)>,
    sigma: f64,
    (w, s): (f64, f64),
) -> MixtureEval<T> {
    let Some((tail, tail_param)) = tail else {
        return MixtureEval {
            f: core,
            d_weight: T::splat(0.0),
            d_ratio: T::splat(0.0),
            d_param: core_param,
        };
    };
    let mix = |a: T, b: T| a * (1.0 - w) + b * w;
    MixtureEval {
        f: CdrfEval {
            value: mix(core.value, tail.value),
            d_theta: mix(core.d_theta, tail.d_theta),
            d2_theta: mix(core.d2_theta, tail.d2_theta),
            d_sigma: mix(core.d_sigma, tail.d_sigma * s),
        },
        d_weight: tail.value - core.value,
        d_ratio: tail.d_sigma * (w * sigma),
        d_param: mix(core_param, tail_param),
    }
}
