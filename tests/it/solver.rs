//! The solver core: parameter mapping and Jacobian against finite differences, and recovery of
//! known parameters from observations rendered by the model itself.

use crate::common;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use workbench::fit::solver::{self, from_unbounded, to_unbounded, Obs, Prior, Problem};
use workbench::model::{idx, Geometry, Model, Params, SpecularParams, N_PARAMS};

/// The plain model's parameters free, η and the extensions held.
fn plain_free() -> [bool; N_PARAMS] {
    let mut free = [true; N_PARAMS];
    free[idx::ETA] = false;
    free[idx::SIGMA_EXPONENT] = false;
    free[idx::ALBEDO_CURVATURE] = false;
    free[idx::KERNEL_WEIGHT] = false;
    free[idx::KERNEL_RATIO] = false;
    free
}

/// The material and light of the synthetic sessions.
fn truth() -> Params {
    let cfg = workbench::synth::session::SessionConfig::default();
    Params {
        material: cfg.material,
        light: cfg.light,
    }
}

/// Observations on the visible hemispheres of spheres of the given radii, seen along +z
/// (view (0, 0, −1)), rendered by the model with relative Gaussian noise.
fn observations(p: &Params, radii: &[f64], per_sphere: usize, noise: f64, seed: u64) -> Vec<Obs> {
    let model = Model::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let gauss = Normal::new(0.0, 1.0).unwrap();
    let mut out = vec![];
    for &r in radii {
        let mut k = 0;
        while k < per_sphere {
            // Uniform over the image disc (as pixels are).
            let (x, y): (f64, f64) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let s2 = x * x + y * y;
            if s2 >= 0.98 {
                continue;
            }
            let n = Vector3::new(x, y, -(1.0 - s2).sqrt());
            let g = Geometry {
                normal: n,
                view: Vector3::new(0.0, 0.0, -1.0),
                radius_mm: r,
            };
            let l = model.radiance(p, &g);
            let sd = 0.002;
            out.push(Obs {
                geometry: g,
                radiance: [0, 1, 2].map(|c| {
                    l[c] * (1.0 + noise * gauss.sample(&mut rng)) + sd * gauss.sample(&mut rng)
                }),
                weight: [1.0; 3],
            });
            k += 1;
        }
    }
    out
}

#[test]
fn mapping_round_trips_and_its_derivative_matches_differences() {
    // One Gaussian (w = 0) stays exactly one: w maps to the bottom of its range and back to 0.
    let plain = truth().to_vec();
    assert_eq!(plain[idx::KERNEL_WEIGHT], 0.0);
    let (back, d) = from_unbounded(&to_unbounded(&plain));
    assert_eq!(back[idx::KERNEL_WEIGHT], 0.0);
    assert_eq!(d[idx::KERNEL_WEIGHT], 0.0);
    // A two-Gaussian kernel, so that every coordinate's mapping is exercised.
    let mut t = truth();
    t.material.kernel_weight = 0.3;
    t.material.kernel_ratio = 2.5;
    let p = t.to_vec();
    let u = to_unbounded(&p);
    let (back, d) = from_unbounded(&u);
    for k in 0..N_PARAMS {
        assert!((back[k] - p[k]).abs() < 1e-14 * (1.0 + p[k].abs()), "{k}");
        let fd = common::derivative(
            &|t: f64| {
                let mut v = u;
                v[k] = t;
                from_unbounded(&v).0[k]
            },
            u[k],
            1e-4,
        );
        assert!(
            (fd - d[k]).abs() < 1e-8 * (1.0 + d[k].abs()),
            "{k}: {fd} vs {}",
            d[k]
        );
    }
}

#[test]
fn jacobian_matches_finite_differences() {
    let mut p = truth();
    // Non-zero extensions, and a prior, so that their rows are checked too.
    p.material.sigma_exponent = 0.3;
    p.material.albedo_curvature = 0.1;
    let priors = vec![Prior {
        index: idx::ETA,
        mean: 1.5,
        std: 0.05,
    }];
    let obs = observations(&p, &[30.0, 15.0], 40, 0.0, 3);
    let free = [true; N_PARAMS];
    let base = Problem {
        model: Model::default(),
        obs: &obs,
        free,
        u: to_unbounded(&p.to_vec()),
        priors: priors.clone(),
        history: None,
        floor: false,
    };
    let (_, j) = base.evaluate(true);
    assert_eq!(j.as_ref().unwrap().nrows(), 3 * obs.len() + 1);
    let j = j.unwrap();
    for k in 0..N_PARAMS {
        for row in (0..j.nrows()).step_by(7) {
            let fd = common::derivative(
                &|t: f64| {
                    let mut q = Problem {
                        model: Model::default(),
                        obs: &obs,
                        free,
                        u: base.u,
                        priors: priors.clone(),
                        history: None,
                        floor: false,
                    };
                    q.u[k] = t;
                    q.evaluate(false).0[row]
                },
                base.u[k],
                1e-4,
            );
            let a = j[(row, k)];
            assert!(
                (fd - a).abs() < 1e-6 * (1.0 + a.abs()),
                "param {k} row {row}: {fd} vs {a}"
            );
        }
    }
}

#[test]
fn recovers_known_parameters_from_a_bad_start() {
    let p = truth();
    let obs = observations(&p, &[35.0, 25.0, 15.0], 3000, 0.01, 11);
    let mut start = p;
    start.material.sigma0_mm = [12.0, 9.0, 6.6];
    start.material.albedo = [0.5, 0.4, 0.3];
    start.material.specular = SpecularParams {
        ks: 2.0,
        alpha: 0.15,
    };
    start.light.azimuth += 10f64.to_radians();
    start.light.elevation -= 8f64.to_radians();
    // η held at its true value: with ks free it is not identifiable (notes §4).
    let free = plain_free();
    let f = solver::fit(Model::default(), &obs, &start, free, &[]);
    assert!(f.converged, "{}", f.termination);
    let (got, want) = (f.params.to_vec(), p.to_vec());
    for k in 0..6 {
        let rel = (got[k] - want[k]).abs() / want[k];
        println!(
            "{}: {:.5} (truth {:.5}) ± {:.5}",
            workbench::model::PARAM_NAMES[k],
            got[k],
            want[k],
            f.std[k]
        );
        assert!(rel < 0.01, "param {k}: {} vs {}", got[k], want[k]);
        assert!(
            (got[k] - want[k]).abs() < 4.0 * f.std[k] + 1e-9,
            "param {k}: error beyond 4 std"
        );
    }
    let light = f
        .params
        .light
        .direction()
        .angle(&p.light.direction())
        .to_degrees();
    println!(
        "light error {light:.4}°, {} evaluations, {}",
        f.evaluations, f.termination
    );
    // Measured: σ0, albedo within 0.33% (2.4 std at most), light 0.0053°.
    assert!(light < 0.02, "{light}");
    assert!((f.params.material.specular.alpha - 0.1).abs() < 0.01);
    assert_eq!(f.std[idx::ETA], 0.0);
    assert_eq!(f.correlation.nrows(), N_PARAMS - 5);
    // The cost history ends at the final cost and never ends above its start.
    assert!(f.history.len() >= f.evaluations.min(2));
    assert!(
        (f.history.last().unwrap() - f.cost).abs() <= 1e-9 * f.cost.max(1e-12) + 1e-12
            || f.history.iter().any(|c| (c - f.cost).abs() < 1e-9 * f.cost)
    );
    assert!(f.cost < f.history[0]);
}

#[test]
fn huber_reweighting_ignores_a_few_bad_pixels() {
    let p = truth();
    let mut obs = observations(&p, &[30.0, 15.0], 2000, 0.01, 5);
    // 3% of the pixels wrong by a factor of three (dust, a reflection).
    for o in obs.iter_mut().step_by(33) {
        o.radiance = o.radiance.map(|v| 3.0 * v + 0.05);
    }
    let free = plain_free();
    let plain = solver::fit(Model::default(), &obs, &p, free, &[]);
    let (robust, weights, down) =
        solver::fit_robust(Model::default(), &obs, &p, free, &[], false, 1.345, 8);
    assert!(down >= 3 * (obs.len() / 33), "{down} down-weighted");
    let err = |f: &solver::Fit| {
        (0..6)
            .map(|k| (f.params.to_vec()[k] - p.to_vec()[k]).abs() / p.to_vec()[k])
            .fold(0.0, f64::max)
    };
    println!(
        "worst relative error of σ0 and albedo: plain {:.4}, Huber {:.4}",
        err(&plain),
        err(&robust)
    );
    assert!(err(&plain) > 0.03, "the outliers should pull a plain fit");
    assert!(err(&robust) < 0.01, "{}", err(&robust));
    // The bad pixels end with small weights.
    let bad: f64 = weights.iter().step_by(33).map(|o| o.weight[1]).sum::<f64>()
        / (weights.len() / 33 + 1) as f64;
    assert!(bad < 0.2, "{bad}");
}

#[test]
fn pooled_cells_fit_like_every_pixel_and_the_predicted_shift_says_how_far() {
    let p = truth();
    let radii = [35.0, 25.0, 15.0];
    let per = 20000;
    let obs = observations(&p, &radii, per, 0.01, 21);
    let free = plain_free();
    let full = solver::fit(Model::default(), &obs, &p, free, &[]);
    let l = p.light.direction();
    let mut pooled = workbench::fit::reduce::Pooled::new(l, (3.0f64 * 0.1).atan());
    for (k, chunk) in obs.chunks(per).enumerate() {
        pooled.add_sphere(k, chunk, None);
    }
    assert_eq!(pooled.pixels, obs.len());
    let mut measured = vec![];
    for factor in [2u32, 4, 8, 16] {
        let deg = factor as f64 * 0.25;
        let mut cells = pooled.merged(factor);
        cells.extend(pooled.highlight_cells(1));
        let reduced = pooled.observations(&cells);
        // The pixel count and radiance sums are kept exactly.
        let n: f64 = cells.iter().map(|c| c.n).sum::<f64>();
        assert_eq!(n as usize, obs.len());
        let f = solver::fit(Model::default(), &reduced, &p, free, &[]);
        // Largest difference from the all-pixel fit, in units of that fit's standard error.
        let z = (0..6)
            .map(|k| (f.params.to_vec()[k] - full.params.to_vec()[k]).abs() / full.std[k])
            .fold(0.0, f64::max);
        let predicted = pooled
            .shift(&cells, &[], &Model::default(), &full.params, free)
            .max_std;
        let light = f
            .params
            .light
            .direction()
            .angle(&full.params.light.direction())
            .to_degrees();
        println!(
            "cells {deg}°: {} observations from {} ({:.0}×), σ0/albedo within {z:.2} std of the full fit (predicted shift {predicted:.2} std), light {light:.4}°",
            reduced.len(),
            obs.len(),
            obs.len() as f64 / reduced.len() as f64
        );
        assert!(reduced.len() < obs.len());
        if deg <= 1.0 {
            assert!(z < 1.0, "{deg}°: {z}");
            assert!(light < 0.02, "{deg}°: {light}");
        }
        measured.push((z, predicted));
    }
    // The prediction grows with the width as the measured shift does, and is of its size where
    // pooling matters (the measured shift also holds a noise part of order 0.1 std).
    for w in measured.windows(2) {
        assert!(w[1].1 > w[0].1, "{measured:?}");
    }
    let (z4, p4) = measured[3];
    assert!(
        z4 > 1.0 && p4 > 0.5 * z4 && p4 < 2.0 * z4,
        "4°: measured {z4}, predicted {p4}"
    );
}

#[test]
fn a_prior_combines_with_the_data_as_two_gaussians_do() {
    let p = truth();
    let mut obs = observations(&p, &[35.0, 25.0, 15.0], 3000, 0.01, 13);
    // Weights 1/σ of the noise the observations were made with, so that the data's residuals
    // and the prior's are in the same units.
    let model = Model::default();
    for o in obs.iter_mut() {
        let l = model.radiance(&p, &o.geometry);
        o.weight = l.map(|v| 1.0 / (0.01f64 * v).hypot(0.002));
    }
    let mut free = plain_free();
    free[idx::ETA] = true;
    let data = solver::fit(model, &obs, &p, free, &[]);
    let prior = Prior {
        index: idx::ETA,
        mean: 1.5,
        std: 0.01,
    };
    let both = solver::fit(model, &obs, &p, free, &[prior]);
    let (m1, s1) = (data.params.material.eta, data.std[idx::ETA]);
    let (w1, w2) = (1.0 / (s1 * s1), 1.0 / (prior.std * prior.std));
    let mean = (m1 * w1 + prior.mean * w2) / (w1 + w2);
    let std = (w1 + w2).sqrt().recip();
    println!(
        "η from the data {m1:.4} ± {s1:.4}; with the prior 1.5 ± 0.01: {:.4} ± {:.4}; product of the two Gaussians {mean:.4} ± {std:.4}",
        both.params.material.eta, both.std[idx::ETA]
    );
    assert!(both.converged && data.converged);
    assert!(
        (both.params.material.eta - mean).abs() < 0.2 * std,
        "posterior mean"
    );
    assert!(
        (both.std[idx::ETA] / std - 1.0).abs() < 0.1,
        "posterior std"
    );
}

/// The normal equations are accumulated per channel over that channel's own parameters and
/// scattered once per chunk: with every parameter free (extensions and a two-Gaussian kernel
/// active), unequal weights and some channels left out (weight 0), they equal JᵀJ, Jᵀr and rᵀr of
/// the Jacobian `evaluate` forms row by row.
#[test]
fn normal_equations_equal_the_product_of_the_jacobian() {
    let mut p = truth();
    p.material.sigma_exponent = 0.2;
    p.material.albedo_curvature = 0.1;
    p.material.kernel_weight = 0.3;
    p.material.kernel_ratio = 2.5;
    p.material.eta = 1.45;
    // More than one chunk of 2048 observations.
    let mut obs = observations(&p, &[35.0, 20.0, 12.0], 1500, 0.01, 5);
    for (i, o) in obs.iter_mut().enumerate() {
        o.weight = [
            if i % 11 == 0 {
                0.0
            } else {
                1.0 + (i % 5) as f64
            },
            2.0 - 0.1 * (i % 7) as f64,
            if i % 13 == 0 { 0.0 } else { 0.5 },
        ];
    }
    let mut start = p;
    start.material.sigma0_mm = [5.0, 3.5, 2.0];
    start.material.eta = 1.3;
    start.light.azimuth += 0.02;
    let problem = Problem {
        model: Model::default(),
        obs: &obs,
        free: [true; N_PARAMS],
        u: to_unbounded(&start.to_vec()),
        priors: vec![],
        history: None,
        floor: false,
    };
    let (r, j) = problem.evaluate(true);
    let j = j.unwrap();
    let ne = problem.normal_equations();
    let (jtj, jtr) = (j.transpose() * &j, j.transpose() * &r);
    let rel = (&ne.jtj - &jtj).amax() / jtj.amax();
    let rel_r = (&ne.jtr - &jtr).amax() / jtr.amax();
    // Measured: 5e-16 and 2e-15 (summation order).
    println!("JᵀJ {rel:.1e}, Jᵀr {rel_r:.1e}");
    assert!(rel < 1e-13 && rel_r < 1e-13, "{rel:e} {rel_r:e}");
    assert!((ne.rtr_obs - r.norm_squared()).abs() < 1e-13 * r.norm_squared());
    // Every parameter reaches the matrix (no column left out of the per-channel layout).
    assert!((0..N_PARAMS).all(|k| ne.jtj[(k, k)] > 0.0));
}

/// The observations with a dark floor added to each channel.
/// The problem on `obs` with a dark floor profiled out, no priors, `free` fitted, at `u`.
fn floored(obs: &[Obs], free: [bool; N_PARAMS], u: [f64; N_PARAMS]) -> Problem<'_> {
    Problem {
        model: Model::default(),
        obs,
        free,
        u,
        priors: vec![],
        history: None,
        floor: true,
    }
}

fn with_floor(obs: &[Obs], floor: [f64; 3]) -> Vec<Obs> {
    obs.iter()
        .map(|o| {
            let mut o = *o;
            for (v, f) in o.radiance.iter_mut().zip(&floor) {
                *v += f;
            }
            o
        })
        .collect()
}

#[test]
fn floor_profiled_out_jacobian_matches_differences_and_the_normal_equations() {
    let p = truth();
    let mut obs = with_floor(
        &observations(&p, &[30.0, 15.0], 40, 0.01, 3),
        [0.01, 0.02, 0.005],
    );
    // Unequal weights, so that the projection on them is exercised.
    for (i, o) in obs.iter_mut().enumerate() {
        o.weight = [
            1.0 + (i % 5) as f64,
            2.0 - 0.1 * (i % 7) as f64,
            0.5 + (i % 3) as f64,
        ];
    }
    let free = plain_free();
    let mut start = p;
    start.material.sigma0_mm = [5.0, 3.5, 2.0];
    let problem = |u: [f64; N_PARAMS]| floored(&obs, free, u);
    let base = problem(to_unbounded(&start.to_vec()));
    let (r, j) = base.evaluate(true);
    let j = j.unwrap();
    let cols: Vec<usize> = (0..N_PARAMS).filter(|&k| free[k]).collect();
    assert_eq!(j.ncols(), cols.len());
    for (a, &k) in cols.iter().enumerate() {
        for row in (0..j.nrows()).step_by(5) {
            let fd = common::derivative(
                &|t: f64| {
                    let mut u = base.u;
                    u[k] = t;
                    problem(u).evaluate(false).0[row]
                },
                base.u[k],
                1e-4,
            );
            assert!(
                (fd - j[(row, a)]).abs() < 1e-6 * (1.0 + j[(row, a)].abs()),
                "param {k} row {row}: {fd} vs {}",
                j[(row, a)]
            );
        }
    }
    // The normal equations (accumulated without forming J) agree with J̃ᵀJ̃, J̃ᵀr̃ and r̃ᵀr̃.
    let ne = base.normal_equations();
    let (jtj, jtr) = (j.transpose() * &j, j.transpose() * &r);
    let scale = jtj.amax();
    assert!((&ne.jtj - &jtj).amax() < 1e-10 * scale, "JᵀJ");
    assert!(
        (&ne.jtr - &jtr).amax() < 1e-10 * jtr.amax().max(1e-300),
        "Jᵀr"
    );
    assert!((ne.rtr_obs - r.norm_squared()).abs() < 1e-10 * r.norm_squared());
    // Each channel's residuals are orthogonal to its weights (the floor took their projection).
    for c in 0..3 {
        let wr: f64 = obs
            .iter()
            .enumerate()
            .map(|(i, o)| o.weight[c] * r[3 * i + c])
            .sum();
        assert!(wr.abs() < 1e-10 * r.amax(), "channel {c}: wᵀr̃ = {wr}");
    }
}

#[test]
fn a_dark_floor_is_fitted_with_the_material() {
    let p = truth();
    let floor = [0.004, 0.003, 0.002];
    let free = plain_free();
    let mut errs = vec![];
    for seed in 0..8 {
        let obs = with_floor(
            &observations(&p, &[35.0, 25.0, 15.0], 3000, 0.01, 100 + seed),
            floor,
        );
        let f = solver::fit_with_floor(Model::default(), &obs, &p, free, &[], true);
        assert!(f.converged, "{}", f.termination);
        let fl = f.floor.expect("the floor is fitted");
        for (c, truth) in floor.iter().enumerate() {
            let e = fl.value[c] - truth;
            errs.push(e / fl.std[c]);
            let s = (f.params.material.sigma0_mm[c] - p.material.sigma0_mm[c]) / f.std[c];
            errs.push(s);
            if seed == 0 {
                println!(
                    "channel {c}: floor {:.5} ± {:.5} (truth {}), σ0 {:.4} ± {:.4} (truth {})",
                    fl.value[c],
                    fl.std[c],
                    floor[c],
                    f.params.material.sigma0_mm[c],
                    f.std[c],
                    p.material.sigma0_mm[c]
                );
            }
        }
        if seed == 0 {
            // Without the floor the same data give a σ0 many standard errors off.
            let plain = solver::fit(Model::default(), &obs, &p, free, &[]);
            for c in 0..3 {
                let off = (plain.params.material.sigma0_mm[c] - p.material.sigma0_mm[c]) / f.std[c];
                println!("channel {c}: σ0 without the floor {off:.1} of the floor fit's std off");
                assert!(
                    off.abs() > 5.0,
                    "channel {c}: the floor should matter ({off:.1})"
                );
            }
        }
    }
    // The stated errors describe the scatter: the mean squared pull of the floor and σ0 is about 1.
    let chi2 = errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64;
    println!("mean squared pull over {} values: {chi2:.2}", errs.len());
    assert!((0.4..2.0).contains(&chi2), "{chi2}");
    assert!(errs.iter().all(|e| e.abs() < 4.0), "{errs:?}");
}

/// Observations of three radii with a dark floor and unequal weights, and each one's radius group.
fn grouped_observations() -> (Vec<Obs>, Vec<usize>) {
    let p = truth();
    let radii = [30.0, 20.0, 15.0];
    let mut obs = with_floor(&observations(&p, &radii, 60, 0.0, 5), [0.01, 0.02, 0.005]);
    for (i, o) in obs.iter_mut().enumerate() {
        o.weight = [1.0 + (i % 5) as f64, 2.0 - 0.1 * (i % 7) as f64, 0.5];
    }
    let groups = (0..obs.len()).map(|i| i / 60).collect();
    (obs, groups)
}

#[test]
fn grouped_normal_equations_are_those_of_each_subset() {
    let (obs, groups) = grouped_observations();
    let mut start = truth();
    start.material.sigma0_mm = [4.5, 3.2, 2.4];
    let priors = vec![Prior {
        index: idx::ETA,
        mean: 1.45,
        std: 0.05,
    }];
    fn problem<'a>(obs: &'a [Obs], start: &Params, priors: &[Prior]) -> Problem<'a> {
        Problem {
            model: Model::default(),
            obs,
            free: plain_free(),
            u: to_unbounded(&start.to_vec()),
            priors: priors.to_vec(),
            history: None,
            floor: true,
        }
    }
    let all = problem(&obs, &start, &priors);
    let parts = all.grouped_sums(Some((&groups, 3)));
    let total = solver::RawNormal::sum(&parts).unwrap();
    let close = |a: &solver::Normal, b: &solver::Normal, what: &str| {
        let rel = (&a.jtj - &b.jtj).amax() / b.jtj.amax();
        let rel_r = (&a.jtr - &b.jtr).amax() / b.jtr.amax();
        let rel_rr = (a.rtr_obs - b.rtr_obs).abs() / b.rtr_obs;
        // Measured: below 1e-14 (summation order).
        assert!(
            rel < 1e-12 && rel_r < 1e-12 && rel_rr < 1e-12,
            "{what}: {rel:e} {rel_r:e} {rel_rr:e}"
        );
    };
    close(
        &all.profiled(&total),
        &all.normal_equations(),
        "the parts' sum",
    );
    for (g, part) in parts.iter().enumerate() {
        // The group's own part, and the totals less it, against the problem of just those rows.
        let own: Vec<Obs> = (0..obs.len())
            .filter(|&i| groups[i] == g)
            .map(|i| obs[i])
            .collect();
        let rest: Vec<Obs> = (0..obs.len())
            .filter(|&i| groups[i] != g)
            .map(|i| obs[i])
            .collect();
        close(
            &all.profiled(part),
            &problem(&own, &start, &priors).normal_equations(),
            "a part",
        );
        close(
            &all.profiled(&total.less(part)),
            &problem(&rest, &start, &priors).normal_equations(),
            "the rest",
        );
    }
}

/// The leave-one-group-out estimate as Newton steps from the full fit (the linear jackknife)
/// against the fit of the subset itself: on noisy observations with a dark floor, the first step
/// from the totals less the group, then steps on the subset, land on the subset's fit to a small
/// fraction of its formal standard error, and the floor they imply is the subset fit's.
#[test]
fn newton_steps_from_the_full_fit_reach_the_fit_without_a_group() {
    let t = truth();
    let radii = [30.0, 20.0, 15.0];
    let obs = with_floor(&observations(&t, &radii, 400, 0.01, 9), [0.01, 0.02, 0.005]);
    let groups: Vec<usize> = (0..obs.len()).map(|i| i / 400).collect();
    let free = plain_free();
    let fit = |o: &[Obs], start: &Params| {
        solver::fit_with_floor(Model::default(), o, start, free, &[], true)
    };
    let full = fit(&obs, &t);
    fn at(obs: &[Obs], u: [f64; N_PARAMS]) -> Problem<'_> {
        floored(obs, plain_free(), u)
    }
    let u_full = to_unbounded(&full.params.to_vec());
    let whole = at(&obs, u_full);
    let parts = whole.grouped_sums(Some((&groups, 3)));
    let total = solver::RawNormal::sum(&parts).unwrap();
    let mut worst = [0.0f64; 3];
    for (g, part) in parts.iter().enumerate() {
        let rest: Vec<Obs> = (0..obs.len())
            .filter(|&i| groups[i] != g)
            .map(|i| obs[i])
            .collect();
        let refit = fit(&rest, &full.params);
        let mut est = whole.newton_step(&total.less(part)).unwrap();
        let mut per_step = vec![];
        for _ in 0..3 {
            let p = from_unbounded(&est.0).0;
            let r = refit.params.to_vec();
            per_step.push(
                (0..N_PARAMS)
                    .filter(|&k| free[k])
                    .map(|k| (p[k] - r[k]).abs() / refit.std[k])
                    .fold(0.0, f64::max),
            );
            let sub = at(&rest, est.0);
            est = sub.newton_step(&sub.grouped_sums(None)[0]).unwrap();
        }
        let floor = refit.floor.unwrap().value;
        let floor_std = refit.floor.unwrap().std;
        let fe = (0..3)
            .map(|c| (est.1[c] - floor[c]).abs() / floor_std[c])
            .fold(0.0, f64::max);
        println!("group {g}: off the refit by {per_step:?} formal std after 1, 2, 3 steps; floor after 4: {fe:.1e} std");
        worst = [
            worst[0].max(per_step[0]),
            worst[1].max(per_step[2]),
            worst[2].max(fe),
        ];
    }
    // Measured: 0.077, 1.3e-5 and 3.9e-7 (the floor after a fourth step).
    assert!(worst[0] < 0.25, "first step {worst:?}");
    assert!(worst[1] < 4e-5, "third step {worst:?}");
    assert!(worst[2] < 1.2e-6, "floor {worst:?}");
}

/// How the other parameters follow the light held elsewhere ([`Problem::follows`], −H_oo⁻¹ H_og
/// at the fit with the light free) against finite differences: the fits with the light's
/// azimuth and elevation held ±ε from the fitted ones (on noisy observations with a dark floor),
/// each parameter's central difference in unbounded units.
#[test]
fn how_the_parameters_follow_the_light_matches_differences() {
    let t = truth();
    // Noise-free observations: at the fit the residuals vanish and JᵀJ is the Hessian (with
    // the pixels' noise, 0.2% absolute, the two differ by up to 2% here: the slopes' Gauss–Newton
    // approximation).
    let model = Model::default();
    let exact: Vec<Obs> = observations(&t, &[30.0, 20.0, 15.0], 400, 0.0, 11)
        .into_iter()
        .map(|o| Obs {
            radiance: model.radiance(&t, &o.geometry),
            ..o
        })
        .collect();
    let obs = with_floor(&exact, [0.01, 0.02, 0.005]);
    let free = plain_free();
    let full = solver::fit_with_floor(Model::default(), &obs, &t, free, &[], true);
    let u = to_unbounded(&full.params.to_vec());
    let problem = floored(&obs, free, u);
    let raw = problem.grouped_sums(None).swap_remove(0);
    let follows = problem
        .follows(&raw, &[idx::AZIMUTH, idx::ELEVATION])
        .unwrap();
    let mut held = free;
    held[idx::AZIMUTH] = false;
    held[idx::ELEVATION] = false;
    let eps = 1e-3;
    let mut worst = 0.0f64;
    for (j, k_light) in [idx::AZIMUTH, idx::ELEVATION].into_iter().enumerate() {
        // The held optimum by Newton steps from the fit (a fixed point of them is the optimum,
        // whatever the approximate Hessian).
        let at = |s: f64| {
            let mut v = u;
            v[k_light] += s * eps;
            for _ in 0..8 {
                let q = floored(&obs, held, v);
                v = q.newton_step(&q.grouped_sums(None)[0]).unwrap().0;
            }
            v
        };
        let (plus, minus) = (at(1.0), at(-1.0));
        for (k, g) in &follows {
            let diff = (plus[*k] - minus[*k]) / (2.0 * eps);
            let scale = g[j].abs().max(diff.abs()).max(1e-3);
            worst = worst.max((g[j] - diff).abs() / scale);
            println!(
                "parameter {k} along light {j}: {:.5} against {diff:.5}",
                g[j]
            );
        }
    }
    // Measured: the largest relative difference 5.6e-4 (ε = 1e-3 rad).
    assert_eq!(follows.len(), free.iter().filter(|&&f| f).count() - 2);
    assert!(worst < 1.5e-3, "largest relative difference {worst}");
}
