//! The paper's procedure run beside a joint fit ([`crate::fit::paper`]), for the figures and a
//! comparison: on the photos less the joint fit's dark floor when it fitted one (the procedure
//! assumes a measured floor).

use super::settings::{Measured, Settings};
use crate::fit::observe::SphereData;
use crate::fit::paper;
use crate::fit::solver::Floor;
use crate::formats::fit::BaselineJson;
use crate::model::LightAngles;
use std::time::Instant;

/// The baseline on `fitted` (less `floor`), or `None` without the detector's light.
pub(crate) fn baseline(
    settings: &Settings,
    measured: &Measured,
    fitted: &[&SphereData],
    floor: Option<Floor>,
) -> Option<BaselineJson> {
    let light = measured.light?;
    let t = Instant::now();
    let floored: Vec<SphereData> = match floor {
        Some(fl) => fitted.iter().map(|s| s.less_floor(fl.value)).collect(),
        None => vec![],
    };
    let base: Vec<&SphereData> = if floored.is_empty() {
        fitted.to_vec()
    } else {
        floored.iter().collect()
    };
    let pf = paper::fit(
        &base,
        &light,
        measured.highlight_radius,
        settings.eta_prior.0,
    );
    let a = LightAngles::from_direction(&light);
    Some(BaselineJson {
        eta: pf.eta,
        light_azimuth_deg: a.azimuth.to_degrees(),
        light_elevation_deg: a.elevation.to_degrees(),
        mask_deg: pf.mask_deg,
        sigma0_mm: pf.params.material.sigma0_mm,
        albedo: pf.params.material.albedo,
        per_radius: pf.per_radius,
        seconds: t.elapsed().as_secs_f64(),
    })
}
