//! The light's irradiance from a diffuse reference in one of the photos (session.json's
//! `"reference"`: a grey card or a reflectance standard of known reflectance ρ): a matte card
//! facing the light has radiance ρE/π, one facing the camera ρE cos θ/π with θ between the
//! camera's axis and the light. Its pixels are read as the spheres' are (linear, over the photo's
//! exposure and light intensity, less the photo's dark floor), averaged over `box_px`, and
//! E = π L / (ρ cos θ) per channel; the fit takes their mean (docs/formats.md, session.json).

use super::load::Loaded;
use super::options::Options;
use crate::error::{Error, Result};
use crate::formats::session::{Facing, SessionReference};
use nalgebra::Vector3;

/// The irradiance a reference gave.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    /// The channels' mean, in the photos' radiance units: what the fit takes.
    pub irradiance: f64,
    pub per_channel: [f64; 3],
    pub image: String,
    pub pixels: usize,
    /// Facing the camera: tan θ × the detected light's error (radians), the irradiance's relative
    /// error from cos θ; 0 facing the light.
    pub relative_std: f64,
}

/// Channels whose irradiance differs from their mean by more than this are said in a note (a
/// coloured light, or a card that is not grey).
const COLOURED: f64 = 0.03;

/// The irradiance from session.json's reference, when it has one: `Ok(None)` without. Its
/// box's pixels were read as the photos were decoded ([`crate::fit::observe::ReferencePixels`]).
pub fn from_reference(l: &Loaded) -> Result<Option<Reference>> {
    let Some((px, floor)) = &l.reference else {
        return Ok(None);
    };
    let r = &px.reference;
    let bad = |msg: String| Error::invalid(&l.report.session_file, format!("reference: {msg}"));
    let info = &l.report.images[px.image];
    let [x0, y0, x1, y1] = r.box_px;
    if x1 > info.width || y1 > info.height {
        return Err(bad(format!(
            "box_px [{x0}, {y0}, {x1}, {y1}] reaches past {} ({}×{})",
            r.image, info.width, info.height
        )));
    }
    clear_of_spheres(l, px.image, r).map_err(bad)?;
    if let Some([x, y]) = px.clipped {
        return Err(bad(format!(
            "pixel ({x}, {y}) of {} is clipped: expose the card below full scale",
            r.image
        )));
    }
    let exposure = info.exposure.unwrap_or(1.0);
    let intensity = info.light_intensity.unwrap_or([1.0; 3]);
    // Less the photo's dark floor, as the spheres' pixels (radiance units).
    let floor = floor.unwrap_or([0.0; 3]);
    let cos = incidence(l, r.facing).map_err(bad)?;
    let relative_std = match r.facing {
        Facing::Light => 0.0,
        Facing::Camera => {
            let tan = (1.0 - cos * cos).max(0.0).sqrt() / cos;
            tan * l.detections.light_std_deg.unwrap_or(f64::NAN).to_radians()
        }
    };
    let per_channel: [f64; 3] = std::array::from_fn(|c| {
        let radiance = (px.sum[c] / px.pixels as f64 / exposure - floor[c]) / intensity[c];
        std::f64::consts::PI * radiance / (r.reflectance * cos)
    });
    if !per_channel.iter().all(|e| e.is_finite() && *e > 0.0) {
        return Err(bad(format!(
            "the box in {} is black (irradiance {per_channel:?}): is it on the card?",
            r.image
        )));
    }
    Ok(Some(Reference {
        irradiance: per_channel.iter().sum::<f64>() / 3.0,
        per_channel,
        image: r.image.clone(),
        pixels: px.pixels,
        relative_std,
    }))
}

/// `opts` with the reference's irradiance when `--irradiance` is not given, and the reference.
pub(super) fn apply(opts: &Options, l: &Loaded) -> Result<(Option<Reference>, Options)> {
    let reference = match opts.fit.irradiance {
        Some(_) => None,
        None => from_reference(l)?,
    };
    let mut with = opts.clone();
    if let Some(r) = &reference {
        with.fit.irradiance = Some(r.irradiance);
    }
    Ok((reference, with))
}

/// Where a given irradiance came from, as fit.json's medium says it.
pub(super) fn source(reference: Option<&Reference>) -> String {
    reference.map_or("given (--irradiance)".to_string(), |r| {
        format!("the diffuse reference in {} (session.json)", r.image)
    })
}

/// The note a reference's irradiance gets: where it came from, and its channels when they differ.
pub fn note(r: &Reference) -> String {
    let mean = r.irradiance;
    let spread = r
        .per_channel
        .iter()
        .map(|e| (e / mean - 1.0).abs())
        .fold(0.0, f64::max);
    let colour = if spread > COLOURED {
        format!(
            "; its channels differ by up to {:.0}% (r, g, b {:.4}, {:.4}, {:.4}): a coloured light or a card that is not grey, and the fit takes one irradiance for all",
            100.0 * spread,
            r.per_channel[0],
            r.per_channel[1],
            r.per_channel[2]
        )
    } else {
        String::new()
    };
    let tilt = if r.relative_std > 0.0 {
        format!(
            "; facing the camera, it carries the light's error through cos θ: ± {:.2}%",
            100.0 * r.relative_std
        )
    } else {
        String::new()
    };
    format!(
        "irradiance {mean:.6} from the diffuse reference in {} ({} pixels, session.json), as --irradiance would give it{tilt}{colour}",
        r.image, r.pixels
    )
}

/// cos θ between the card's normal and the light: 1 facing the light; facing the camera, the
/// light's angle from the camera's axis (the detected light), which must be well in front.
fn incidence(l: &Loaded, facing: Facing) -> std::result::Result<f64, String> {
    match facing {
        Facing::Light => Ok(1.0),
        Facing::Camera => {
            let light = l.detections.light_direction.map(Vector3::from).ok_or(
                "facing the camera needs the light's direction, and the detector found none",
            )?;
            // The card faces the camera: its normal points back along −z.
            let cos = -light.z;
            if cos < 0.1 {
                return Err(format!(
                    "facing the camera, the card sees the light at {:.0}° from its normal: too grazing to measure (face it to the light)",
                    cos.clamp(-1.0, 1.0).acos().to_degrees()
                ));
            }
            Ok(cos)
        }
    }
}

/// The box must stay off every sphere of its photo (their outlines, 2 pixels padded).
fn clear_of_spheres(l: &Loaded, k: usize, r: &SessionReference) -> std::result::Result<(), String> {
    let info = &l.report.images[k];
    let [x0, y0, x1, y1] = r.box_px;
    for (j, s) in l.detections.images[k].spheres.iter().enumerate() {
        let Some([sx0, sy0, sx1, sy1]) =
            s.outline
                .outline()
                .pixel_box(&l.proj, 2.0, info.width, info.height)
        else {
            continue;
        };
        if x0 <= sx1 && sx0 < x1 && y0 <= sy1 && sy0 < y1 {
            return Err(format!(
                "box_px [{x0}, {y0}, {x1}, {y1}] overlaps sphere {j} of {} (pixels {sx0}–{sx1}, {sy0}–{sy1})",
                r.image
            ));
        }
    }
    Ok(())
}
