//! `detections.json` (schema `workbench.detections/2`): what `workbench detect` found in a
//! session's photos — each sphere's outline and highlight, each photo's light and the session's —
//! as the fit and the renderer's check read it.

use crate::camera::outline::Outline;
use crate::camera::sphere::EllipseJson;
use crate::formats::session::LightMode;
use nalgebra::{Vector2, Vector3};
use serde::{Deserialize, Serialize};

pub(crate) const SCHEMA: &str = "workbench.detections/2";

/// A fitted outline, as stored.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum OutlineJson {
    /// Perspective: the tangent cone (unit axis toward the centre, half-angle).
    Cone { axis: [f64; 3], half_angle_deg: f64 },
    /// Orthographic: a circle in pixels.
    Circle { center_px: [f64; 2], radius_px: f64 },
}

impl From<&Outline> for OutlineJson {
    fn from(o: &Outline) -> Self {
        match o {
            Outline::Cone { axis, half_angle } => OutlineJson::Cone {
                axis: [axis.x, axis.y, axis.z],
                half_angle_deg: half_angle.to_degrees(),
            },
            Outline::Circle { center, radius } => OutlineJson::Circle {
                center_px: [center.x, center.y],
                radius_px: *radius,
            },
        }
    }
}

impl OutlineJson {
    pub fn outline(&self) -> Outline {
        match *self {
            OutlineJson::Cone {
                axis,
                half_angle_deg,
            } => Outline::Cone {
                axis: Vector3::from(axis).normalize(),
                half_angle: half_angle_deg.to_radians(),
            },
            OutlineJson::Circle {
                center_px,
                radius_px,
            } => Outline::Circle {
                center: Vector2::from(center_px),
                radius: radius_px,
            },
        }
    }
}

/// The highlight of one sphere.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HighlightJson {
    pub method: Method,
    /// Fitted GGX roughness (lobe fit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha: Option<f64>,
    /// Its standard error: formal, with the diffuse trend's and the clipping's share (lobe fit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_std: Option<f64>,
    pub saturated_px: usize,
    /// Angular radius around the mirror direction whose pixels are flagged as highlight.
    pub radius_deg: f64,
    /// Left out of the combined light (more than 5σ from the others).
    pub outlier: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SphereDetection {
    pub radius_mm: f64,
    /// Silhouette in ideal (undistorted pinhole) pixels.
    pub ellipse: EllipseJson,
    pub center_mm: Option<[f64; 3]>,
    pub outline: OutlineJson,
    /// 1-σ of the outline's centre (x, y) and radius, px.
    pub silhouette_std_px: [f64; 3],
    /// Fitted edge blur (Gaussian σ, px) beyond the pixel footprint.
    pub silhouette_blur_px: f64,
    /// Photos the silhouette was fitted over (more than 1: the sphere stayed put between them).
    pub silhouette_photos: usize,
    pub edge_points: usize,
    pub edge_inliers: usize,
    pub highlight_px: Option<[f64; 2]>,
    pub light_direction: Option<[f64; 3]>,
    pub light_std_deg: Option<f64>,
    pub highlight: Option<HighlightJson>,
    /// Why no highlight was used, when none was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_highlight: Option<String>,
    pub samples: Counts,
    /// The outline drawn for the medium fit (`detect --model medium`, `solve --model medium`):
    /// each sector of the rim weighed by its contrast as well as its noise, since a translucent
    /// sphere's dim stretches of rim draw the outline inward (docs/measurements/detection.md,
    /// "Each sector weighted by its rim's contrast"). The medium's pixels are seated on it;
    /// `outline` above, which the highlights, the light and the CDRF use, is the same whichever
    /// model asked. Absent where the medium was not asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub medium_outline: Option<MediumOutlineJson>,
}

/// The outline drawn for the medium fit, with its 1-σ errors (centre x, y and radius, px).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MediumOutlineJson {
    pub outline: OutlineJson,
    pub std_px: [f64; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageDetection {
    pub file: String,
    pub width: u32,
    pub height: u32,
    /// Relative exposure dividing the samples' radiance (null: unknown).
    pub exposure: Option<f64>,
    /// What the EXIF reader lost, substituted or ignored, one line each.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exif_notes: Vec<String>,
    /// Combined over this photo's spheres.
    pub light_direction: Option<[f64; 3]>,
    pub light_std_deg: Option<f64>,
    pub spheres: Vec<SphereDetection>,
    /// The overlay picture, relative to detections.json.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overlay: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Detections {
    pub schema: String,
    /// The session file, as given.
    pub session: String,
    /// "perspective" (with intrinsics) or "orthographic" (none given).
    pub projection: String,
    pub light: LightMode,
    /// Combined over the session (null under `"light": "per-image"` or without highlights).
    pub light_direction: Option<[f64; 3]>,
    pub light_std_deg: Option<f64>,
    /// How far each sphere's light scatters beyond its own error (degrees; 0 where they agree;
    /// null without a session light): a disturbed outline or highlight. Included in
    /// `light_std_deg` (`detect::highlight::combine`).
    pub light_scatter_deg: Option<f64>,
    /// Azimuth and elevation of the combined light (degrees; see `model::LightAngles`).
    pub light_azimuth_deg: Option<f64>,
    pub light_elevation_deg: Option<f64>,
    pub images: Vec<ImageDetection>,
    pub seconds: f64,
    /// What it was made from: session.json, the photos and the intrinsics, each as
    /// `"<bytes>:<hash>"` (`crate::formats::fingerprint`); reused only while they match.
    #[serde(default)]
    pub inputs: crate::formats::fingerprint::Inputs,
    /// The workbench build that made it (`crate::formats::fingerprint::BUILD`); reused only by
    /// the same build.
    #[serde(default)]
    pub build: String,
    /// Read, never written: builds of 2026-12-07 before `medium_outline` wrote `"contrast"` here
    /// where `outline` itself had been drawn for the medium, so that such a file is not
    /// reused (`solve` detects again).
    #[serde(default, skip_serializing)]
    pub edge_weights: Option<String>,
}

impl Detections {
    /// Whether every sphere has the outline drawn for the medium fit
    /// ([`SphereDetection::medium_outline`]).
    pub fn has_medium_outlines(&self) -> bool {
        self.images
            .iter()
            .flat_map(|i| &i.spheres)
            .all(|s| s.medium_outline.is_some())
    }
}

/// How a highlight was located.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// GGX lobe fitted to the highlight's pixels (a highlight resolved by the pixels).
    LobeFit,
    /// Intensity-weighted centroid of the excess over a local plane (a highlight a few pixels
    /// wide, or clipped with too little of its lobe left).
    Centroid,
}

/// Counts of a sphere's samples, as `detections.json` reports them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Counts {
    pub total: usize,
    pub saturated: usize,
    pub edge: usize,
    pub highlight: usize,
}
