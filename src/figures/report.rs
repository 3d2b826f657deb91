//! The fit report: `index.html` beside a fit's figures, self-contained (no scripts, no fonts, no
//! links outside the folder except to fit.json), so it opens offline. It shows the parameters with
//! their standard errors and status (fitted, fixed, held at a prior, off), the error per sphere,
//! the held-out prediction, the paper's baseline, what was skipped, the notes, and every figure
//! (PNG, linked to its SVG).

use crate::error::Result;
use crate::formats::fit::{FitFile, Method};
use crate::plot::Figure;
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// A figure and its file stem, with a caption for the index.
pub struct Named {
    pub name: String,
    pub caption: String,
    pub figure: Figure,
}

/// Escape text for HTML.
pub fn escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// A value and its standard error with digits enough for the error's two leading figures.
pub(crate) fn with_error(v: f64, e: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if !(e.is_finite() && e > 0.0) {
        return format!("{v:.5}");
    }
    let digits = (1 - e.log10().floor() as i32).clamp(0, 8) as usize;
    format!("{v:.digits$} ± {e:.digits$}")
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1500px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border-bottom:1px solid #ddd;padding:3px 10px;text-align:left}\
td.n{text-align:right;font-variant-numeric:tabular-nums}figure{margin:1.5em 0}img{max-width:100%;border:1px solid #eee}\
figcaption{color:#444;margin-top:0.3em}.bad{color:#b2182b;font-weight:bold}";

/// Write `dir/index.html` for a fit and its figures: the fit's headline, its parameters, the
/// error per sphere, the per-radius fits, what was skipped and the notes, the figures.
pub(crate) fn write_index(
    fit: &FitFile,
    fit_path: &Path,
    figures: &[Named],
    dir: &Path,
) -> Result<PathBuf> {
    let mut h = [
        heading(fit, fit_path),
        parameters(fit),
        spheres(fit),
        per_radius(fit),
        lists(fit),
        figure_list(figures),
    ]
    .concat();
    h.push_str("</body></html>\n");
    let path = dir.join("index.html");
    crate::formats::output::write_bytes(&path, h.as_bytes())?;
    Ok(path)
}

/// The page's head and the fit's headline.
fn heading(fit: &FitFile, fit_path: &Path) -> String {
    let mut h = String::new();
    let method = match fit.method {
        Method::Joint => "joint fit",
        Method::Paper => "paper's baseline method",
    };
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>workbench fit: {}</title><style>{STYLE}</style></head><body>\n",
        escape(&fit.session)
    );
    let _ = writeln!(h, "<h1>Fit of {}</h1>", escape(&fit.session));
    let _ = writeln!(
        h,
        "<p>{method}, {} camera; solver {}; relative RMSE {:.2}% of the data's RMS. File: <code>{}</code> (schema {}).</p>",
        escape(&fit.projection),
        if fit.convergence.converged {
            "converged".to_string()
        } else {
            "<span class=\"bad\">did not converge</span>".to_string()
        },
        100.0 * fit.rmse.relative,
        escape(&fit_path.display().to_string()),
        escape(&fit.schema)
    );
    h
}

/// Each parameter with its error and status, and the light's direction.
fn parameters(fit: &FitFile) -> String {
    let mut h = String::new();
    h.push_str("<h2>Parameters</h2>\n<table><tr><th>parameter</th><th>value ± standard error</th><th>status</th></tr>\n");
    for p in &fit.parameters {
        let (v, e, unit) = match p.name.as_str() {
            "light_azimuth" | "light_elevation" => (p.value.to_degrees(), p.std.to_degrees(), " °"),
            n if n.starts_with("sigma0") => (p.value, p.std, " mm"),
            _ => (p.value, p.std, ""),
        };
        let shown = if p.status.starts_with("off") {
            "—".to_string()
        } else {
            format!("{}{unit}", with_error(v, e))
        };
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            escape(&p.name),
            escape(&shown),
            escape(&p.status)
        );
    }
    h.push_str("</table>\n");
    let _ = writeln!(
        h,
        "<p>Light direction (camera frame, pointing to the light): [{:+.5}, {:+.5}, {:+.5}], ± {:.3}°.</p>",
        fit.light_direction[0], fit.light_direction[1], fit.light_direction[2], fit.std.light_deg
    );
    h
}

/// The error per sphere, and the held-out radius's.
fn spheres(fit: &FitFile) -> String {
    let mut h = String::new();
    h.push_str("<h2>Error per sphere</h2>\n<table><tr><th>photo</th><th>sphere</th><th>radius (mm)</th><th>pixels used</th><th>saturated</th><th>edge</th><th>relative RMSE</th><th>lit</th><th>unlit</th><th></th></tr>\n");
    for s in &fit.rmse.spheres {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{:.2}%</td><td class=\"n\">{:.2}%</td><td class=\"n\">{:.2}%</td><td>{}</td></tr>",
            escape(&s.image),
            s.index + 1,
            s.radius_mm,
            s.pixels,
            s.saturated,
            s.edge,
            100.0 * s.rel_rmse,
            100.0 * s.lit_rel_rmse,
            100.0 * s.unlit_rel_rmse,
            if s.held_out { "held out" } else { "" }
        );
    }
    h.push_str("</table>\n");
    if let Some(ho) = &fit.holdout {
        let _ = writeln!(
            h,
            "<p>Held-out radius {} mm ({} pixels) predicted with relative RMSE {:.2}% (lit {:.2}%, unlit {:.2}%).</p>",
            ho.radius_mm,
            ho.pixels,
            100.0 * ho.rel_rmse,
            100.0 * ho.lit_rel_rmse,
            100.0 * ho.unlit_rel_rmse
        );
    }
    h
}

/// The per-radius fits (the paper's baseline, or the paper's method itself).
fn per_radius(fit: &FitFile) -> String {
    let mut h = String::new();
    let per_radius = fit
        .baseline
        .as_ref()
        .map(|b| (&b.per_radius, "The paper's baseline beside the joint fit"))
        .or(fit.per_radius.as_ref().map(|p| (p, "Per-radius fits")));
    if let Some((rows, title)) = per_radius {
        let _ = writeln!(h, "<h2>{title}</h2>");
        if let Some(b) = &fit.baseline {
            let _ = writeln!(
                h,
                "<p>Light from the detector (azimuth {:.2}°, elevation {:.2}°), exit Fresnel divided out with η = {}, pixels within {:.1}° of the mirror direction masked. Combined σ0: {:.4}, {:.4}, {:.4} mm.</p>",
                b.light_azimuth_deg, b.light_elevation_deg, b.eta, b.mask_deg,
                b.sigma0_mm[0], b.sigma0_mm[1], b.sigma0_mm[2]
            );
        }
        h.push_str("<table><tr><th>radius (mm)</th><th>spheres</th><th>pixels</th><th>σ0 red (mm)</th><th>σ0 green (mm)</th><th>σ0 blue (mm)</th></tr>\n");
        for r in rows {
            let _ = writeln!(
                h,
                "<tr><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                r.radius_mm,
                r.spheres,
                r.pixels,
                with_error(r.sigma0_mm[0], r.sigma0_std[0]),
                with_error(r.sigma0_mm[1], r.sigma0_std[1]),
                with_error(r.sigma0_mm[2], r.sigma0_std[2])
            );
        }
        h.push_str("</table>\n");
    }
    h
}

/// What was skipped or reused, and the notes.
fn lists(fit: &FitFile) -> String {
    let mut h = String::new();
    for (title, items) in [("Skipped or reused", &fit.skipped), ("Notes", &fit.notes)] {
        if !items.is_empty() {
            let _ = writeln!(h, "<h2>{title}</h2>\n<ul>");
            for i in items {
                let _ = writeln!(h, "<li>{}</li>", escape(i));
            }
            h.push_str("</ul>\n");
        }
    }
    h
}

/// Every figure, linked to its SVG.
fn figure_list(figures: &[Named]) -> String {
    let mut h = String::new();
    h.push_str("<h2>Figures</h2>\n<p>Each picture links to its SVG.</p>\n");
    for f in figures {
        let _ = writeln!(
            h,
            "<figure id=\"{n}\"><a href=\"{n}.svg\"><img src=\"{n}.png\" alt=\"{c}\" width=\"{w}\"></a><figcaption>{c}</figcaption></figure>",
            n = escape(&f.name),
            c = escape(&f.caption),
            w = f.figure.size.0
        );
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_and_rounds() {
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
        assert_eq!(with_error(1.23456, 0.0123), "1.235 ± 0.012");
        assert_eq!(with_error(0.5, 0.0), "0.50000");
        assert_eq!(with_error(123.4, 5.0), "123.4 ± 5.0");
    }
}
