//! A sphere as found in one photo: its silhouette (fitted outline, its errors, the edge points
//! kept) and its highlight, or why it has none.

use crate::camera::outline::{Outline, Projection};
use crate::detect::highlight::{self, Highlight};
use crate::detect::silhouette::Plane;
use crate::formats::photo::LinearRgb;
use nalgebra::Vector2;

/// A sphere's silhouette as found in one photo (or fitted over several).
#[derive(Clone, Debug)]
pub struct Silhouette {
    pub radius_mm: f64,
    pub outline: Outline,
    pub std_px: [f64; 3],
    pub blur_px: f64,
    /// Photos the outline was fitted over (more than one: a sphere that stayed put).
    pub photos: usize,
    /// Noise level of the photo (luminance units).
    pub noise: f64,
    pub edge_points: usize,
    pub inlier_px: Vec<Vector2<f64>>,
    /// The outline drawn for the medium fit (the rim weighed by its contrast too,
    /// [`crate::detect::silhouette::EdgeModel::Medium`]), where it was asked for.
    pub medium: Option<MediumOutline>,
}

/// An outline drawn for the medium fit, and its 1-σ errors (centre x, y and radius, px).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumOutline {
    pub outline: Outline,
    pub std_px: [f64; 3],
}

/// Everything found on one sphere, before serialisation.
#[derive(Clone, Debug)]
pub struct Found {
    pub silhouette: Silhouette,
    /// The highlight, or why there is none.
    pub highlight: std::result::Result<Highlight, String>,
}

/// Locate the highlight on every sphere of a photo (once its outlines are final).
pub(crate) fn locate_highlights(
    img: &LinearRgb,
    lum: &Plane,
    proj: &Projection,
    spheres: Vec<Silhouette>,
) -> Vec<Found> {
    spheres
        .into_iter()
        .map(|s| Found {
            highlight: highlight::find(lum, &img.saturated, proj, &s.outline, s.noise)
                .map_err(|e| e.0),
            silhouette: s,
        })
        .collect()
}
