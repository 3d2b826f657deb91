//! Newton steps from a joint fit on its final stage's problem ([`super::stages::FinalProblem`]):
//! the linear jackknife's estimates without a radius ([`super::jackknife`]) and the fit with the
//! light held ([`super::session`]) start from the fit and take the Gauss–Newton steps of the
//! problem changed, with the Huber weights taken again at each, as the iteratively reweighted
//! fit does, from close by.

use super::stages::{JointFit, HUBER_K};
use crate::fit::solver::{self, from_unbounded, to_unbounded, Obs, Problem};
use crate::model::{Params, N_PARAMS};

/// An estimate: the unbounded parameters and the dark floor.
pub(crate) type Estimate = ([f64; N_PARAMS], [f64; 3]);

/// The final stage's problem of `jf` on `obs` (all or some of its observations, with their
/// weights) with `free` fitted, at `u`.
pub(crate) fn problem<'a>(
    jf: &JointFit,
    obs: &'a [Obs],
    free: [bool; N_PARAMS],
    u: [f64; N_PARAMS],
) -> Problem<'a> {
    Problem {
        model: jf.model,
        obs,
        free,
        u,
        priors: jf.problem.priors.clone(),
        history: None,
        floor: jf.fit.floor.is_some(),
    }
}

/// Where the iteration ended.
pub(crate) struct Iterated {
    pub estimate: Estimate,
    /// The observations with the Huber weights of the last step.
    pub weighted: Vec<Obs>,
    /// Newton steps taken, `first` included.
    pub steps: u32,
    /// The last step was within `tol` (else `max_steps` ran out).
    pub converged: bool,
}

/// Newton steps on `obs` (without robust weights; `weighted`, with those of the step before)
/// from `first`, itself a step, with `free` fitted: the Huber weights are taken again before
/// each (with the Huber loss), and the steps go on while one moves a parameter by more than its
/// `tol` (unbounded coordinates; at least one more with the Huber loss, whose weights `first`
/// kept), at most `max_steps` in all. With `give_up_stalled`, the iteration also ends, not
/// converged, at a step no shorter than the one two before it: a converging reweighted Newton
/// iteration contracts (by ~4× a step on the physically based wax), and one that does not
/// contract over two steps was measured not to settle in [`super::hold::HOLD_STEPS`] either
/// (DiLiGenT's ball: steps of 760, 1782, 905 … their tolerance for 16 steps). `None` where a
/// step failed (singular normal equations).
pub(crate) fn iterate(
    jf: &JointFit,
    (obs, mut weighted): (&[Obs], Vec<Obs>),
    free: [bool; N_PARAMS],
    (start, first): (&[f64; N_PARAMS], Estimate),
    tol: &[f64; N_PARAMS],
    (max_steps, give_up_stalled): (u32, bool),
) -> Option<Iterated> {
    let robust = jf.problem.robust;
    // A step's length: its largest move in units of the tolerance.
    let length = |a: &[f64; N_PARAMS], b: &[f64; N_PARAMS]| {
        (0..N_PARAMS)
            .filter(|&k| free[k])
            .map(|k| (a[k] - b[k]).abs() / tol[k])
            .fold(0.0, f64::max)
    };
    let large = |a: &[f64; N_PARAMS], b: &[f64; N_PARAMS]| length(a, b) > 1.0;
    let mut lengths = vec![length(start, &first.0)];
    let mut cur = first;
    let mut done = !robust && !large(start, &first.0);
    let mut steps = 1;
    while !done && steps < max_steps {
        let n = lengths.len();
        if give_up_stalled && n >= 3 && lengths[n - 1] >= lengths[n - 3] {
            break;
        }
        if robust {
            let p = Params::from_vec(&from_unbounded(&cur.0).0);
            weighted = solver::huber_weights(&jf.model, obs, &weighted, &p, cur.1, HUBER_K).0;
        }
        let pr = problem(jf, &weighted, free, cur.0);
        let next = pr.newton_step(&pr.grouped_sums(None)[0])?;
        lengths.push(length(&cur.0, &next.0));
        done = !large(&cur.0, &next.0);
        cur = next;
        steps += 1;
    }
    Some(Iterated {
        estimate: cur,
        weighted,
        steps,
        converged: done,
    })
}

/// Per parameter, [`STEP_TOL`] of the larger of its formal standard error in `jf` and `spread`
/// (unbounded coordinates): the largest step that ends an iteration.
pub(crate) fn tolerance(jf: &JointFit, spread: &[f64; N_PARAMS]) -> [f64; N_PARAMS] {
    let dpdu = from_unbounded(&to_unbounded(&jf.fit.params.to_vec())).1;
    std::array::from_fn(|k| {
        let formal = jf.fit.std[k] / dpdu[k].abs();
        STEP_TOL
            * if formal.is_finite() {
                formal.max(spread[k])
            } else {
                spread[k]
            }
    })
}

/// An iteration goes on while its last step moved a parameter by more than this fraction of the
/// larger of its formal standard error and the spread it is for.
pub(crate) const STEP_TOL: f64 = 0.05;
