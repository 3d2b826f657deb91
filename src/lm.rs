//! The one small Levenberg–Marquardt step of the detector's dense fits (the outline through edge
//! points, the silhouette's edge model, the highlight's lobe): the normal equations
//! JᵀJ δ = −Jᵀr damped by (1 + λ) on the diagonal, the step handed to the caller, which maps it to a trial point (bounds, step limits)
//! and evaluates its cost; a lower cost is accepted and λ shrinks by 0.3 (down to `lambda_min`),
//! anything else raises λ tenfold and tries again, `tries` times at most.
//!
//! The joint fit is larger and needs a trust region without bounds: it uses the
//! `levenberg-marquardt` crate (MINPACK's algorithm) through [`crate::fit::solver`].

use nalgebra::{SMatrix, SVector};

/// The damping state of one fit.
#[derive(Clone, Copy, Debug)]
pub struct Lm {
    pub lambda: f64,
    pub lambda_min: f64,
    /// Trial steps per iteration before giving up.
    pub tries: usize,
    /// Added to the damped diagonal so that a parameter the data do not touch stays solvable.
    pub tiny: f64,
}

impl Lm {
    /// One iteration from a point of cost `cost`: `trial` maps a step to a trial point and
    /// returns its cost and whatever the caller keeps of it (`None`: outside the domain, a
    /// rejection). Returns the accepted trial's cost and state, or `None` when every try was
    /// rejected (the fit has converged or is stuck).
    pub fn step<const N: usize, S>(
        &mut self,
        jtj: &SMatrix<f64, N, N>,
        jtr: &SVector<f64, N>,
        cost: f64,
        mut trial: impl FnMut(&SVector<f64, N>) -> Option<(f64, S)>,
    ) -> Option<(f64, S)> {
        for _ in 0..self.tries {
            let mut m = *jtj;
            for d in 0..N {
                m[(d, d)] *= 1.0 + self.lambda;
                m[(d, d)] += self.tiny;
            }
            if let Some(step) = m.try_inverse().map(|mi| -(mi * jtr)) {
                if let Some((c, s)) = trial(&step) {
                    if c < cost {
                        self.lambda = (self.lambda * 0.3).max(self.lambda_min);
                        return Some((c, s));
                    }
                }
            }
            self.lambda *= 10.0;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    /// Rosenbrock's valley as residuals r = (10(y − x²), 1 − x): the damped steps reach (1, 1),
    /// each accepted step lowering the cost.
    #[test]
    fn reaches_the_rosenbrock_minimum() {
        let res = |p: &Vector2<f64>| Vector2::new(10.0 * (p.y - p.x * p.x), 1.0 - p.x);
        let jac = |p: &Vector2<f64>| Matrix2::new(-20.0 * p.x, 10.0, -1.0, 0.0);
        let mut lm = Lm {
            lambda: 1e-3,
            lambda_min: 1e-12,
            tries: 12,
            tiny: 1e-300,
        };
        let mut p = Vector2::new(-1.2, 1.0);
        let mut cost = res(&p).norm_squared();
        for _ in 0..200 {
            let (r, j) = (res(&p), jac(&p));
            let Some((c, q)) = lm.step(&(j.transpose() * j), &(j.transpose() * r), cost, |d| {
                let q = p + d;
                Some((res(&q).norm_squared(), q))
            }) else {
                break;
            };
            assert!(c < cost);
            (p, cost) = (q, c);
        }
        assert!((p - Vector2::new(1.0, 1.0)).norm() < 1e-8, "{p}");
    }

    /// A trial outside the domain is a rejection: λ grows until the step is short enough.
    #[test]
    fn rejections_raise_the_damping() {
        let mut lm = Lm {
            lambda: 1e-3,
            lambda_min: 1e-9,
            tries: 10,
            tiny: 0.0,
        };
        let jtj = Matrix2::identity();
        let jtr = Vector2::new(-1.0, 0.0); // undamped step (1, 0)
        let got = lm.step(&jtj, &jtr, 1.0, |d| (d.x < 0.01).then_some((0.5, d.x)));
        let (c, x) = got.unwrap();
        assert_eq!(c, 0.5);
        // The step 1/(1 + λ) is first below 0.01 at λ = 100; λ is then 0.3 of that.
        assert!(
            (x - 1.0 / 101.0).abs() < 1e-9 && (lm.lambda - 30.0).abs() < 1e-9,
            "{x} {}",
            lm.lambda
        );
        // Every try rejected: None, λ raised `tries` times.
        let before = lm.lambda;
        assert!(lm.step(&jtj, &jtr, 1.0, |_| None::<(f64, ())>).is_none());
        assert!((lm.lambda / before - 1e10).abs() < 1e-3);
    }
}
