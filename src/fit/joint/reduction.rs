//! The reduction level (docs/pipeline.md, step 4): how many residuals the joint stage sees —
//! (θ, φ) cells of the pooled pixels ([`crate::fit::reduce`]), the highlight in pixel blocks —
//! chosen as the coarsest whose predicted parameter shifts stay within tolerance.

use super::settings::Reduction;
use crate::fit::observe::SphereData;
use crate::fit::reduce::Pooled;
use crate::fit::solver::Obs;
use crate::formats::fit::Level;
use crate::model::{Model, Params, N_PARAMS, PARAM_NAMES};

/// Largest predicted shift of any parameter that a reduction level may cause (in standard errors;
/// or below the parameter's [`crate::fit::reduce::tolerance`]).
pub(crate) const SHIFT_LIMIT: f64 = crate::fit::reduce::SHIFT_STD;

/// The highlight region pooled in pixel blocks, in detector highlight radii.
pub(crate) const HIGHLIGHT_KEEP: f64 = 1.0;

/// Block sizes (pixels) tried for the highlight, smallest first: a block's bias grows with its
/// size (about 4× a doubling), so the first one out of tolerance ends the search, usually the
/// first one tried (docs/pipeline.md, step 4).
pub(crate) const HIGHLIGHT_BLOCKS: [u32; 4] = [2, 4, 8, 16];

/// The reduction level (docs/pipeline.md, step 4): angular cells first (the highlight pixel by
/// pixel), then the highlight's pixel blocks, each the coarsest whose predicted shift is within
/// tolerance under `Reduction::Auto`. Returns the observations the joint stage fits with the
/// sphere each comes from (its index in `spheres`), the level chosen (width 0: every pixel) and
/// the levels tried.
pub(crate) fn choose_reduction(
    reduction: Reduction,
    pooled: &Pooled,
    spheres: &[&SphereData],
    model: &Model,
    p: &Params,
    free: [bool; N_PARAMS],
) -> (Vec<Obs>, Vec<usize>, Level, Vec<Level>) {
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
    let (final_obs, sphere) = match &chosen_cells {
        Some(cells) => (
            pooled.observations(cells),
            cells.iter().map(|c| c.sphere).collect(),
        ),
        // Every pixel.
        None => (
            spheres.iter().flat_map(|s| s.obs.iter().cloned()).collect(),
            spheres
                .iter()
                .enumerate()
                .flat_map(|(i, s)| std::iter::repeat_n(i, s.obs.len()))
                .collect(),
        ),
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
    (final_obs, sphere, chosen, levels)
}
