//! `intrinsics.json` (schema `workbench.intrinsics/1`): a calibrated camera as a file.

use crate::camera::{Camera, Distortion};
use crate::error::{Error, Result};
use crate::formats::output::read_json;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The largest image side accepted (pixels): beyond any camera sensor, and what keeps every
/// per-pixel buffer allocatable.
pub const MAX_IMAGE_SIDE: u32 = 65_536;

pub(crate) const SCHEMA: &str = "workbench.intrinsics/1";

/// Standard deviations of the intrinsics (px, and unitless for distortion).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct IntrinsicsStd {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: Distortion,
}

/// One calibration view's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewReport {
    pub file: String,
    /// RMS reprojection error of this view's corners, px (null when not used).
    pub rms_px: Option<f64>,
    /// "used", "rejected: …" or "no board found".
    pub status: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IntrinsicsFile {
    pub schema: String,
    /// [width, height] in pixels.
    pub image_size: [u32; 2],
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: Distortion,
    /// Overall RMS reprojection error (px); null for a camera that was not calibrated from views.
    pub rms_px: Option<f64>,
    pub std: Option<IntrinsicsStd>,
    #[serde(default)]
    pub views: Vec<ViewReport>,
    /// Where the numbers come from, e.g. "synthetic truth" or "calibrated from 13 views".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// How the calibration was reached (pattern, model choice, cross-validation, EXIF, warnings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub details: Option<serde_json::Value>,
}

impl IntrinsicsFile {
    /// The exact camera of a synthetic scene.
    pub(crate) fn from_truth(cam: &Camera) -> Self {
        IntrinsicsFile {
            schema: SCHEMA.into(),
            image_size: cam.image_size,
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            distortion: cam.distortion,
            rms_px: None,
            std: None,
            views: vec![],
            source: Some("synthetic truth".into()),
            details: None,
        }
    }

    pub fn camera(&self) -> Camera {
        Camera {
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            distortion: self.distortion,
            image_size: self.image_size,
        }
    }

    /// Read and validate an `intrinsics.json`.
    pub fn load(path: &Path) -> Result<Self> {
        let f: IntrinsicsFile = read_json(path)?;
        if f.schema != SCHEMA {
            return Err(Error::invalid(
                path,
                format!("schema is {:?}, expected {SCHEMA:?}", f.schema),
            ));
        }
        let d = f.distortion;
        let finite = [f.fx, f.fy, f.cx, f.cy, d.k1, d.k2, d.p1, d.p2, d.k3]
            .iter()
            .all(|v| v.is_finite());
        if !finite || f.fx <= 0.0 || f.fy <= 0.0 || f.image_size.contains(&0) {
            return Err(Error::invalid(
                path,
                "focal lengths must be positive and all values finite",
            ));
        }
        let [w, h] = f.image_size;
        if w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE {
            return Err(Error::invalid(
                path,
                format!("image_size {w}x{h}: each side must be at most {MAX_IMAGE_SIDE} pixels"),
            ));
        }
        // A field of view between 0.06° and 179.9° across the larger side.
        let side = w.max(h) as f64;
        for (name, v) in [("fx", f.fx), ("fy", f.fy)] {
            if !(side / 1000.0..=1000.0 * side).contains(&v) {
                return Err(Error::invalid(
                    path,
                    format!(
                        "{name} = {v:?} pixels for a {w}x{h} image: a lens between {} and {} pixels (fields of view 179.9° to 0.06°) is expected",
                        side / 1000.0,
                        1000.0 * side
                    ),
                ));
            }
        }
        Ok(f)
    }
}
