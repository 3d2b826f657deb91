//! The one-screen human summary of a fit.

use crate::formats::fit::*;
use std::fmt::Write;

/// The one-screen human summary of a fit: the method, the material, the light, the model's
/// extensions and the baseline, how well it fits, the solver, what was skipped, the notes, the
/// time.
pub fn summary(f: &FitFile) -> String {
    [
        material(f),
        medium(f),
        light(f),
        extensions(f),
        quality(f),
        solver(f),
        time(f),
    ]
    .concat()
}

/// A parameter's status as fit.json gives it.
fn status(f: &FitFile, name: &str) -> String {
    f.parameters
        .iter()
        .find(|p| p.name == name)
        .map(|p| p.status.clone())
        .unwrap_or_default()
}

/// A value and its standard error, to `digits` decimals: `± unbounded` where the data do not
/// bound it (fit.json's `null` with a reason; [`unbounded`]), `± not determined` for a failed
/// fit's.
pub(super) fn pm(v: f64, e: f64, digits: usize) -> String {
    if unbounded(v, e) {
        format!("{v:.digits$} ± unbounded")
    } else if e.is_nan() {
        format!("{v:.digits$} ± not determined")
    } else {
        format!("{v:.digits$} ± {e:.digits$}")
    }
}

/// Three channels' values with their errors, to `digits` decimals.
fn rgb(v: &[f64; 3], e: &[f64; 3], digits: usize) -> String {
    (0..3)
        .map(|c| pm(v[c], e[c], digits))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The medium fit's σa, σs′, η, mean free path and surface albedo, and how well it fits.
fn medium(f: &FitFile) -> String {
    let Some(m) = &f.medium else {
        return String::new();
    };
    let mut s = String::new();
    let row = |s: &mut String, name: &str, p: &PerChannelJson, unit: &str| {
        let _ = writeln!(s, "{name:<8} {}{unit}", rgb(&p.value, &p.std, 4));
    };
    row(&mut s, "sigma_a", &m.sigma_a_per_mm, " /mm (medium)");
    row(&mut s, "sigma_s'", &m.sigma_s_reduced_per_mm, " /mm");
    let _ = writeln!(
        s,
        "eta      {} (medium), mean free path {} mm",
        pm(m.eta.value, m.eta.std, 4),
        rgb(&m.mean_free_path_mm.value, &m.mean_free_path_mm.std, 3)
    );
    let _ = writeln!(
        s,
        "surface  albedo {}; residuals {:.2}× the noise over {} pixel-channels, {} profiles, {:.1} s{}",
        rgb(&m.diffuse_albedo.value, &m.diffuse_albedo.std, 3),
        m.residual_over_noise,
        m.pixels,
        m.profiles,
        m.seconds,
        m.holdout.map_or(String::new(), |h| format!(
            "; held-out {} mm: medium {:.2}%, CDRF {:.2}%",
            h.radius_mm,
            100.0 * h.medium_rel_rmse,
            100.0 * h.cdrf_rel_rmse
        ))
    );
    s
}

/// The method, σ0, the albedo, η and the lobe.
fn material(f: &FitFile) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "method   {} ({} camera), session {}",
        match f.method {
            Method::Joint => "joint",
            Method::Paper => "paper baseline",
        },
        f.projection,
        f.session
    );
    let _ = writeln!(
        s,
        "sigma0   {} mm (r, g, b)",
        rgb(&f.sigma0_mm, &f.std.sigma0_mm, 4)
    );
    let _ = writeln!(s, "albedo   {}", rgb(&f.albedo, &f.std.albedo, 4));
    let _ = writeln!(
        s,
        "eta      {}  [{}]",
        pm(f.eta, f.std.eta, 4),
        status(f, "eta")
    );
    match (&f.specular, &f.std.specular) {
        (Some(sp), Some(e)) => {
            let _ = writeln!(
                s,
                "specular ks {} [{}], alpha {} [{}]",
                pm(sp.ks, e.ks, 4),
                status(f, "ks"),
                pm(sp.alpha, e.alpha, 4),
                status(f, "alpha")
            );
        }
        _ => {
            let _ = writeln!(s, "specular none  [{}]", status(f, "ks"));
        }
    }
    s
}

/// The light, how far it moved from the detector's, and each photo's.
fn light(f: &FitFile) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "light    [{:+.5}, {:+.5}, {:+.5}] (az {:.3}°, el {:.3}°) ± {:.3}°  [{}]",
        f.light_direction[0],
        f.light_direction[1],
        f.light_direction[2],
        f.light_azimuth_deg,
        f.light_elevation_deg,
        f.std.light_deg,
        status(f, "light_azimuth")
    );
    if let Some(lp) = &f.light_pull {
        let _ = writeln!(
            s,
            "         moved {:.3}° from the detector's light (± {:.4}°): pull {:.1}",
            lp.moved_deg, lp.detector_std_deg, lp.pull
        );
    }
    for il in &f.image_lights {
        let lamp = match (il.intensity, il.intensity_source.as_deref()) {
            (Some(k), Some(from)) => {
                format!(", lamp {:.3}, {:.3}, {:.3} ({from})", k[0], k[1], k[2])
            }
            _ => String::new(),
        };
        let _ = writeln!(
            s,
            "light    {:<12} [{:+.5}, {:+.5}, {:+.5}] (az {:.3}°, el {:.3}°){lamp}",
            il.file,
            il.direction[0],
            il.direction[1],
            il.direction[2],
            il.azimuth_deg,
            il.elevation_deg
        );
    }
    s
}

/// The model's extensions, the per-radius fits and the paper's baseline.
fn extensions(f: &FitFile) -> String {
    let mut s = String::new();
    if let (Some(q), Some(e)) = (f.sigma_exponent, f.std.sigma_exponent) {
        let _ = writeln!(
            s,
            "extension sigma_exponent q = {} (r_ref {} mm)",
            pm(q, e, 4),
            f.reference_radius_mm
        );
    }
    if let (Some(k), Some(e)) = (f.kernel, f.std.kernel) {
        let _ = writeln!(
            s,
            "kernel   two Gaussians: weight {} in a tail {} times wider",
            pm(k.weight, e.weight, 4),
            pm(k.ratio, e.ratio, 3)
        );
    }
    if let (Some(b), Some(e)) = (f.albedo_curvature, f.std.albedo_curvature) {
        let _ = writeln!(
            s,
            "extension albedo_curvature b = {} (r_ref {} mm)",
            pm(b, e, 4),
            f.reference_radius_mm
        );
    }
    if let Some(pr) = &f.per_radius {
        for r in pr {
            let _ = writeln!(
                s,
                "radius   {:>6} mm: σ {:.4}, {:.4}, {:.4} rad → σ0 {:.3}, {:.3}, {:.3} mm",
                r.radius_mm,
                r.sigma_rad[0],
                r.sigma_rad[1],
                r.sigma_rad[2],
                r.sigma0_mm[0],
                r.sigma0_mm[1],
                r.sigma0_mm[2]
            );
        }
    }
    if let Some(b) = &f.baseline {
        let _ = writeln!(
            s,
            "baseline paper's method: σ0 {:.4}, {:.4}, {:.4} mm (detector's light, η = {} divided out, peak masked; {:.2} s)",
            b.sigma0_mm[0], b.sigma0_mm[1], b.sigma0_mm[2], b.eta, b.seconds
        );
    }
    s
}

/// The residuals, each sphere's prediction, the jackknife's and the holdout's.
fn quality(f: &FitFile) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "rmse     {:.3e} ({:.2}% of the data's RMS){}",
        f.rmse.overall,
        100.0 * f.rmse.relative,
        f.convergence
            .chi2_per_dof
            .map(|c| format!(", {:.2}× the measured noise (χ²/dof {c:.2})", c.sqrt()))
            .unwrap_or_default()
    );
    for sp in &f.rmse.spheres {
        let _ = writeln!(
            s,
            "sphere   {:<12} #{} r {:>5} mm: {:>8} px, rel. RMSE {:.2}% (lit {:.2}%, unlit {:.2}%){}",
            sp.image,
            sp.index + 1,
            sp.radius_mm,
            sp.pixels,
            100.0 * sp.rel_rmse,
            100.0 * sp.lit_rel_rmse,
            100.0 * sp.unlit_rel_rmse,
            if sp.held_out { "  HELD OUT" } else { "" }
        );
    }
    if let Some(j) = &f.jackknife {
        let per: Vec<String> = j
            .heldout
            .iter()
            .map(|h| format!("{} mm {:.2}%", h.radius_mm, 100.0 * h.rel_rmse))
            .collect();
        let _ = writeln!(
            s,
            "jackknife each radius left out and predicted: {} (mean {:.2}%); std = {}",
            per.join(", "),
            100.0 * j.heldout_rel_rmse,
            f.std_source
        );
    }
    if let Some(h) = &f.holdout {
        let _ = writeln!(
            s,
            "holdout  r {} mm predicted with rel. RMSE {:.2}% (lit {:.2}%, unlit {:.2}%)",
            h.radius_mm,
            100.0 * h.rel_rmse,
            100.0 * h.lit_rel_rmse,
            100.0 * h.unlit_rel_rmse
        );
    }
    s
}

/// The solver's convergence, what was skipped and the notes.
fn solver(f: &FitFile) -> String {
    let mut s = String::new();
    let c = &f.convergence;
    let evals: usize = c.stages.iter().map(|st| st.evaluations).sum();
    let _ = writeln!(
        s,
        "solver   {} ({} stages, {} evaluations{}){}",
        if c.converged {
            "converged"
        } else {
            "DID NOT CONVERGE"
        },
        c.stages.len(),
        evals,
        c.robust_loss
            .as_ref()
            .map(|r| format!(", {r}, {} residuals down-weighted", c.downweighted))
            .unwrap_or_default(),
        c.stages
            .last()
            .map(|st| format!(": {}", st.termination))
            .unwrap_or_default()
    );
    for k in &f.skipped {
        let _ = writeln!(s, "skipped  {k}");
    }
    for n in &f.notes {
        let _ = writeln!(s, "note     {n}");
    }
    s
}

/// Where the time went.
fn time(f: &FitFile) -> String {
    let mut s = String::new();
    let t = &f.timings;
    let _ = writeln!(
        s,
        "time     {:.2} s: detect {:.2}, decode {:.2}, samples {:.2}, solve {:.2}{}{}{}",
        t.total_s,
        t.detect_s,
        t.decode_s,
        t.samples_s,
        t.solve_s,
        if t.model_choice_s > 0.0 {
            format!(", model choice {:.2}", t.model_choice_s)
        } else {
            String::new()
        },
        if t.jackknife_s > 0.0 {
            format!(", jackknife {:.2}", t.jackknife_s)
        } else {
            String::new()
        },
        if t.holdout_s > 0.0 {
            format!(", predictions {:.2}", t.holdout_s)
        } else {
            String::new()
        }
    );
    s
}

#[cfg(test)]
mod tests {
    use super::pm;

    #[test]
    fn unbounded_and_undetermined_errors_are_said_in_words() {
        assert_eq!(pm(1.25, 0.5, 2), "1.25 ± 0.50");
        // An opaque ball's σ0 (issue 34): 1.1e32 mm was printed as a number.
        assert_eq!(pm(0.0012, 1.08e32, 4), "0.0012 ± unbounded");
        assert_eq!(pm(0.5, f64::INFINITY, 1), "0.5 ± unbounded");
        assert_eq!(pm(0.5, f64::NAN, 1), "0.5 ± not determined");
        // Large but bounded: a value of 1000 ± 1e8 is below 1e6 times its value.
        assert_eq!(pm(1000.0, 1e8, 0), "1000 ± 100000000");
    }
}
