//! A joint fit with what the settings ask around it ([`fit_session`]): the extensions (the
//! default, named, or chosen by held-out error), the detector's light and the shading's combined
//! by their covariances, the jackknife, the paper's baseline beside it, and each parameter's stated
//! standard error from all of them.

use super::baseline::baseline;
use super::choice::choose_extensions;
use super::combine::combine_lights;
use super::identify;
use super::jackknife::{jackknife_linear, jackknife_refit, Jackknife};
use super::settings::{
    ExtensionChoice, Extensions, JackknifeMethod, Measured, Settings, Setup,
    DEFAULT_EXTENSION_RADII,
};
use super::stages::{fit_joint, JointFit};
use crate::fit::observe::{self, SphereData};
use crate::formats::fit::{BaselineJson, ModelChoice};
use crate::model::{N_PARAMS, PARAM_NAMES};
use std::time::Instant;

/// What [`fit_session`] returns.
pub struct Session {
    pub fit: JointFit,
    /// The settings the fit ran with: the light's treatment is `Hold` (at `start_light`) where the
    /// light was held at the combination.
    pub settings: Settings,
    /// What was skipped, and why.
    pub skipped: Vec<String>,
    pub model_choice: Option<ModelChoice>,
    pub model_choice_s: f64,
    pub jackknife: Option<Jackknife>,
    pub baseline: Option<BaselineJson>,
    /// Each parameter's stated standard error: the formal one or the jackknife's spread, scaled
    /// for a prior's tension, with the light's systematic (and η's) added in quadrature.
    pub std: [f64; N_PARAMS],
    /// How the light was treated ("prior", "free", "hold", "prior, then combined").
    pub light_fit: String,
}

/// The joint fit of `fitted` with what `settings` ask around it; the notes join `notes`.
pub fn fit_session(
    settings: &Settings,
    measured: &Measured,
    fitted: &[&SphereData],
    notes: &mut Vec<String>,
) -> Session {
    let mut skipped = vec![];
    let (ext, model_choice, model_choice_s) =
        extensions(settings, measured, fitted, &mut skipped, notes);
    // The resolution check waits for the fit that stands: a light held at the combination
    // replaces this fit with one that runs its own.
    let setup = Setup::new(settings, measured, ext, settings.reduction);
    let first = fit_joint(
        &Setup {
            checks: false,
            ..setup
        },
        fitted,
    );
    let first_phases = first.phases.clone();
    let t = Instant::now();
    let held = combine_lights(settings, measured, fitted, ext, first, notes);
    let (mut jf, settings) = (held.fit, held.settings);
    jf.phases = combination_phases(first_phases, jf.phases, t.elapsed().as_secs_f64());
    jf.check_resolution(&setup, fitted);
    let jack = if settings.jackknife != JackknifeMethod::Off {
        let j = match settings.jackknife {
            JackknifeMethod::Refit => jackknife_refit(
                &settings,
                measured,
                fitted,
                &jf,
                Extensions::of_fit(&jf.fit.free),
            ),
            _ => jackknife_linear(fitted, &jf),
        };
        if j.is_none() {
            skipped.push(
                "jackknife: fewer than 3 radii, the standard errors are the formal ones".into(),
            );
        }
        j
    } else {
        skipped.push(
            "jackknife: off (--jackknife off or --no-jackknife), the standard errors are the formal ones".into(),
        );
        None
    };
    notes.extend(floor_note(&jf, measured));
    let baseline = settings
        .baseline
        .then(|| baseline(&settings, measured, fitted, jf.fit.floor))
        .flatten();
    notes.extend(jf.notes.iter().cloned());
    skipped.extend(reduction_skips(&jf));
    let std = stated_std(&jf, jack.as_ref(), &held.light_shift);
    let poorly = poorly_stated(&jf.fit.params.to_vec(), &jf.fit.free, &std, notes);
    notes.extend(poorly);
    let light_fit = if held.combined {
        "prior, then combined".into()
    } else {
        settings.light_fit.name().into()
    };
    Session {
        fit: jf,
        settings,
        skipped,
        model_choice,
        model_choice_s,
        jackknife: jack,
        baseline,
        std,
        light_fit,
    }
}

/// The solve's phases around the light's combination: the first fit's (`first`), then the
/// combination's own seconds (the shading's light and the Newton steps of the held fit) as
/// "light combination", and where the held fit was the whole fit repeated (its phases `last`
/// are not the first's), those after it, named "held: …". `seconds`: the combination's in all.
fn combination_phases(
    first: Vec<(String, f64)>,
    last: Vec<(String, f64)>,
    seconds: f64,
) -> Vec<(String, f64)> {
    let repeated = last != first;
    let repeat_s: f64 = if repeated {
        last.iter().map(|p| p.1).sum()
    } else {
        0.0
    };
    let mut phases = first;
    phases.push(("light combination".into(), (seconds - repeat_s).max(0.0)));
    if repeated {
        phases.extend(last.into_iter().map(|(n, s)| (format!("held: {n}"), s)));
    }
    phases
}

/// The extensions the settings choose, with the model choice and its seconds under `Auto`.
fn extensions(
    settings: &Settings,
    measured: &Measured,
    fitted: &[&SphereData],
    skipped: &mut Vec<String>,
    notes: &mut Vec<String>,
) -> (Extensions, Option<ModelChoice>, f64) {
    match settings.extensions {
        ExtensionChoice::None => (Extensions::default(), None, 0.0),
        ExtensionChoice::On(e) => (e, None, 0.0),
        ExtensionChoice::Default => {
            let radii = observe::distinct_radii(fitted);
            if radii.len() >= DEFAULT_EXTENSION_RADII {
                let e = Extensions {
                    albedo_curvature: true,
                    ..Extensions::default()
                };
                (e, None, 0.0)
            } else {
                skipped.push(format!(
                    "albedo curvature (the default extension): {} radii, it needs {DEFAULT_EXTENSION_RADII}",
                    radii.len()
                ));
                (Extensions::default(), None, 0.0)
            }
        }
        ExtensionChoice::Auto => {
            let t = Instant::now();
            let (mc, e) = choose_extensions(settings, measured, fitted);
            let seconds = t.elapsed().as_secs_f64();
            notes.push(format!("model: {} ({})", mc.chosen, mc.reason));
            (e, Some(mc), seconds)
        }
    }
}

/// The note for a dark floor fitted with the material, in pixel values.
fn floor_note(jf: &JointFit, measured: &Measured) -> Option<String> {
    let fl = jf.fit.floor?;
    let e = measured.pixel_scale;
    let show = |v: [f64; 3]| v.map(|x| format!("{:.5}", x * e)).join(", ");
    Some(format!(
        "no dark floor measured (the photos around the spheres are lit): fitted with the material, {} ± {} of full scale (r, g, b), and subtracted before the predictions and figures",
        show(fl.value),
        show(fl.std)
    ))
}

/// What the fit left out: the lobe, pixels pooled, parameters resting on their priors.
fn reduction_skips(jf: &JointFit) -> Vec<String> {
    let mut skipped = vec![];
    if !jf.specular {
        skipped.push("specular lobe: off (no usable highlight)".into());
    }
    skipped.push(if jf.chosen.width_deg > 0.0 {
        format!(
            "pixels: {} pooled into {} observations ({}° cells, predicted shift {:.2} std)",
            jf.pixels, jf.chosen.observations, jf.chosen.width_deg, jf.chosen.predicted_shift_std
        )
    } else {
        format!("pixels: all {} used", jf.pixels)
    });
    for (name, st) in PARAM_NAMES.iter().zip(&jf.status) {
        if st.starts_with("prior") {
            skipped.push(format!("{name}: {st}"));
        }
    }
    skipped
}

/// Each parameter's stated standard error (docs/uncertainty.md): the larger of the formal error
/// and the jackknife's spread, scaled by its prior's tension, with the light's systematic in
/// quadrature, and the disagreement between two measurements of it (η with the highlight alone
/// and with α at the detector's, α with the detector's lobe fits; [`JointFit::systematic`]).
fn stated_std(
    jf: &JointFit,
    jack: Option<&Jackknife>,
    light_shift: &[f64; N_PARAMS],
) -> [f64; N_PARAMS] {
    std::array::from_fn(|k| {
        let spread = jack.map_or(0.0, |j| j.std[k]);
        (jf.fit.std[k].max(spread) * jf.prior_tension[k])
            .hypot(light_shift[k])
            .hypot(jf.systematic[k])
    })
}

/// Free parameters whose stated error is beyond their plausible range
/// ([`identify::beyond_range`]) where the fit's own was not: the radii's jackknife, the prior's
/// tension or the light's error widened it. Each gets the note the fit's own error would have
/// given ([`identify::hold`]), unless a note names it so already.
fn poorly_stated(
    params: &[f64],
    free: &[bool; N_PARAMS],
    std: &[f64; N_PARAMS],
    notes: &[String],
) -> Vec<String> {
    (0..N_PARAMS)
        .filter(|&k| free[k] && identify::beyond_range(k, params[k], std[k]))
        .filter(|&k| {
            let said = format!("{} is poorly determined", PARAM_NAMES[k]);
            !notes.iter().any(|n| n.starts_with(&said))
        })
        .map(|k| {
            format!(
                "{} is poorly determined (std {:.3} for {:.4} as stated: the fit's own error widened by the radii's jackknife, a prior's tension or the light's error)",
                PARAM_NAMES[k], std[k], params[k]
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{combination_phases, poorly_stated};
    use crate::model::{idx, N_PARAMS};

    /// A stated error past the parameter's plausible range gets the fit's own note (σ0_r ± 1.99
    /// mm for 2.20, more than half of it; η ± 0.6), once: not for one the fit already named, a
    /// held parameter, or one within its range (σ0_g ± 0.7 for 3.4).
    #[test]
    fn a_stated_error_past_its_range_is_said() {
        let mut params = [0.0; N_PARAMS];
        let mut std = [0.0; N_PARAMS];
        let mut free = [false; N_PARAMS];
        for (k, p, s) in [
            (idx::SIGMA0, 2.20, 1.99),
            (idx::SIGMA0 + 1, 3.44, 0.74),
            (idx::SIGMA0 + 2, 2.71, 1.50),
            (idx::ETA, 1.45, 0.6),
            (idx::KS, 0.0, f64::INFINITY),
        ] {
            params[k] = p;
            std[k] = s;
            free[k] = k != idx::KS;
        }
        let said = vec!["sigma0_b is poorly determined (std inf for 2.7100)".to_string()];
        let notes = poorly_stated(&params, &free, &std, &said);
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(notes[0].starts_with("sigma0_r is poorly determined (std 1.990 for 2.2000"));
        assert!(notes[1].starts_with("eta is poorly determined (std 0.600"));
    }

    fn phases(v: &[(&str, f64)]) -> Vec<(String, f64)> {
        v.iter().map(|(n, s)| (n.to_string(), *s)).collect()
    }

    /// A held fit by Newton steps keeps the first fit's phases: the combination's seconds follow
    /// them; a repeated fit's phases follow as "held: …", the combination less their sum.
    #[test]
    fn the_phases_add_up_to_the_combination_and_the_repeat() {
        let first = phases(&[("pool", 1.0), ("joint stage", 4.0)]);
        let newton = combination_phases(first.clone(), first.clone(), 0.5);
        assert_eq!(
            newton,
            phases(&[
                ("pool", 1.0),
                ("joint stage", 4.0),
                ("light combination", 0.5)
            ])
        );
        let repeat = phases(&[("pool", 1.5), ("joint stage", 6.0)]);
        let repeated = combination_phases(first, repeat, 8.25);
        assert_eq!(
            repeated,
            phases(&[
                ("pool", 1.0),
                ("joint stage", 4.0),
                ("light combination", 0.75),
                ("held: pool", 1.5),
                ("held: joint stage", 6.0),
            ])
        );
    }
}
