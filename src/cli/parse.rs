//! The command line's value parsers, one per value shape: `AxB`, `a,b`, `a,b,c` (or one value
//! for all three), `name=MEAN:STD`, and the solve's named choices.

/// "A,E": two finite angles in degrees (azimuth, elevation), as every `a,b` option takes them.
pub(crate) fn angles(s: &str) -> std::result::Result<[f64; 2], String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("expected AZIMUTH,ELEVATION in degrees, got {s:?}"))?;
    Ok([azimuth_arg(a)?, elevation_arg(b)?])
}

/// An azimuth in degrees: finite, within one turn either way.
pub(crate) fn azimuth_arg(s: &str) -> std::result::Result<f64, String> {
    degrees(s, "an azimuth", 360.0)
}

/// An elevation in degrees: within [−90, 90].
pub(crate) fn elevation_arg(s: &str) -> std::result::Result<f64, String> {
    degrees(s, "an elevation", 90.0)
}

/// An angle in degrees from text: a finite number within ±`limit` (`what` names it).
fn degrees(t: &str, what: &str, limit: f64) -> std::result::Result<f64, String> {
    let v = t
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("not a finite number: {t:?}"))?;
    if v.abs() <= limit {
        Ok(v)
    } else {
        Err(format!(
            "{what} must lie in [-{limit}, {limit}] degrees, got {v}"
        ))
    }
}

/// "AxB" as two numbers (`what` names them in the error).
pub(crate) fn parse_dims<T: std::str::FromStr>(
    s: &str,
    form: &str,
    what: &str,
) -> std::result::Result<(T, T), String> {
    let (a, b) = s
        .split_once('x')
        .ok_or_else(|| format!("expected {form}, got {s:?}"))?;
    let p = |t: &str| {
        t.trim()
            .parse::<T>()
            .map_err(|_| format!("not a {what}: {t:?}"))
    };
    Ok((p(a)?, p(b)?))
}

pub(crate) fn parse_resolution(s: &str) -> std::result::Result<(u32, u32), String> {
    parse_dims(s, "WIDTHxHEIGHT", "pixel count")
}

/// A table size: None for auto.
#[derive(Clone, Copy)]
pub(crate) struct TableArg(pub(crate) Option<(usize, usize)>);

pub(crate) fn parse_table_size(s: &str) -> std::result::Result<TableArg, String> {
    if s == "auto" {
        return Ok(TableArg(None));
    }
    parse_dims(s, "auto or N_COSxN_KAPPA", "node count").map(|d| TableArg(Some(d)))
}

pub(crate) fn parse_prior(s: &str) -> std::result::Result<(f64, f64), String> {
    let (name, rest) = s
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=MEAN:STD, got {s:?}"))?;
    if name.trim() != "eta" {
        return Err(format!("priors are offered for eta only, got {name:?}"));
    }
    let (m, sd) = rest
        .split_once(':')
        .ok_or_else(|| format!("expected eta=MEAN:STD, got {s:?}"))?;
    let m: f64 = m.trim().parse().map_err(|_| format!("bad mean {m:?}"))?;
    let sd: f64 = sd.trim().parse().map_err(|_| format!("bad std {sd:?}"))?;
    if !(m > 1.0 && m < 4.0 && sd > 0.0 && sd.is_finite()) {
        return Err(format!("need 1 < mean < 4 and std > 0, got {m}:{sd}"));
    }
    Ok((m, sd))
}

pub(crate) fn parse_reduce(
    s: &str,
) -> std::result::Result<workbench::fit::joint::Reduction, String> {
    use workbench::fit::joint::Reduction;
    match s {
        "auto" => Ok(Reduction::Auto),
        "none" | "0" => Ok(Reduction::None),
        _ => {
            let w: f64 = s
                .parse()
                .map_err(|_| format!("expected auto, none or degrees, got {s:?}"))?;
            let f = (w / 0.25).round() as u32;
            if workbench::fit::reduce::FACTORS.contains(&f) && (f as f64 * 0.25 - w).abs() < 1e-9 {
                Ok(Reduction::Factor(f))
            } else {
                Err(format!(
                    "cell width must be 0.25, 0.5, 1, 2 or 4 degrees, got {s}"
                ))
            }
        }
    }
}

pub(crate) fn parse_extensions(
    s: &str,
) -> std::result::Result<workbench::fit::joint::ExtensionChoice, String> {
    use workbench::fit::joint::ExtensionChoice;
    use workbench::fit::joint::Extensions;
    match s {
        "default" => return Ok(ExtensionChoice::Default),
        "none" => return Ok(ExtensionChoice::None),
        "auto" => return Ok(ExtensionChoice::Auto),
        "both" => {
            return Ok(ExtensionChoice::On(Extensions {
                sigma_exponent: true,
                albedo_curvature: true,
                two_gaussian: false,
            }))
        }
        _ => {}
    }
    let mut e = Extensions::default();
    for part in s.split(',') {
        match part.trim() {
            "sigma-exponent" => e.sigma_exponent = true,
            "albedo-curvature" => e.albedo_curvature = true,
            "two-gaussian" => e.two_gaussian = true,
            other => {
                return Err(format!(
                    "unknown extension {other:?} (sigma-exponent, albedo-curvature, two-gaussian)"
                ))
            }
        }
    }
    Ok(ExtensionChoice::On(e))
}

/// A comma-separated list (an alias, so clap takes it as one value).
pub(crate) type Floats = Vec<f64>;

/// Parse "a,b,c" into floats.
pub(crate) fn floats(s: &str) -> std::result::Result<Floats, String> {
    s.split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .map_err(|_| format!("{t:?} is not a number"))
        })
        .collect()
}

pub(crate) fn triple(s: &str) -> std::result::Result<[f64; 3], String> {
    let v = floats(s)?;
    match v.len() {
        1 => Ok([v[0]; 3]),
        3 => Ok([v[0], v[1], v[2]]),
        _ => Err("give one value or three (r,g,b)".into()),
    }
}
